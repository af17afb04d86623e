"""Basis coefficients w(t, z) from K motion patterns, in torch.

Twin of `velogauss_ref.motion.coefficients` (spec/motion.md, VG-COEF, VG-COEF-RIGID and
VG-COEF-HARM).
The time network runs once per time for all K patterns; particles differ only through their
mixing weights.
"""

import math

import numpy as np
import torch

from velogauss_fast.checks import check_array
from velogauss_fast.motion.basis import basis_matrix
from velogauss_fast.motion.scalars import check_time, time_tensor
from velogauss_fast.nn import mlp, positional_encoding


def coefficients(params, t, z, cfg):
    """w = m(z) P(t), masked by cfg.mask (VG-COEF).

    params: motion parameter dict (uses "mix" and "time"); t: scalar time (number or 0-d
    tensor, any real value); z: (N, L) physics codes; cfg: MotionSpec -> w: (N, 12).
    m(z) = softmax(z A + c) (N, K); P(t) = mlp(time, gamma(t)) reshaped (K, 12), evaluated once
    (the rigid bodies of VG-COEF-RIGID when cfg.pattern_form is "rigid", the oscillators of
    VG-COEF-HARM when "harmonic").
    """
    check_time("t", t)
    check_array("z", z, (None, params["mix"][0][0].shape[0]))
    return mixed_coefficients(params, t, mixing_weights(params, z), cfg)


def mixed_coefficients(params, t, m, cfg):
    """w = m P(t), masked by cfg.mask (VG-COEF from given mixing weights m (N, K); VG-FIELD-GAUSS
    passes interpolated ones) -> (N, 12). Unchecked: callers have validated t and m."""
    return masked(m @ motion_patterns(params, t, cfg), cfg.mask)


def mixing_logits(params, z):
    """z A + c: (N, L) codes -> (N, K) logits of the mixing weights (VG-COEF; VG-LOSS-MIX takes
    them). Unchecked, as `mixing_weights`."""
    A, c = params["mix"][0]
    return z @ A + c


def mixing_weights(params, z):
    """m(z) = softmax(z A + c): (N, L) codes -> (N, K) weights (VG-COEF). Unchecked: callers
    (`coefficients`, the trajectory, the residuals) have validated z."""
    return torch.softmax(mixing_logits(params, z), dim=-1)  # [N, K]


def mixing_weights_jet(params, z, dz):
    """(m(z), its directional derivatives along the tangents dz) (VG-COEF), by hand.

    z: (N, L) codes; dz: (T, N, L) -> m: (N, K) as `mixing_weights`, dm: (T, N, K), from the
    softmax's derivative dm = m (dl - <m, dl>) with dl = dz A the tangents of the logits.
    Unchecked, as `mixing_weights`.
    """
    A, _ = params["mix"][0]
    m = mixing_weights(params, z)
    dl = dz @ A  # [T, N, K]
    return m, m * (dl - (m * dl).sum(-1, keepdim=True))


def motion_patterns(params, t, cfg):
    """P(t) (K, 12): the K motion patterns at the scalar time t (VG-COEF). Unchecked."""
    return motion_patterns_at(params, time_tensor(t, params["time"][0][0]), cfg)[0]  # [K, 12]


def motion_patterns_at(params, times, cfg):
    """P(t) (S, K, 12) at the times (S,) tensor: the time network run once on all of them.
    Under cfg.future "coast" a time past cfg.max_time reads P(max_time) (VG-COEF-COAST). The
    time network's and the oscillators' patterns are written about params["centre"] (K, 3)
    when the dict holds it (VG-COEF-CENTRE)."""
    if cfg.future == "coast":
        times = times.clamp(max=cfg.max_time)
    if cfg.pattern_form == "rigid":
        return rigid_velocity_patterns(params["time"], times[:, None, None], cfg.max_time)
    if cfg.pattern_form == "harmonic":
        return centred(harmonic_velocity_patterns(*params["time"][0], times[:, None, None]), params.get("centre"))
    out = mlp(params["time"], positional_encoding(times[:, None], cfg.n_freqs_t))  # [S, K * 12]
    return centred(out.reshape(times.shape[0], -1, 12), params.get("centre"))


def centred(P, centres):
    """World-frame patterns (..., K, 12) of patterns P (..., K, 12) written about their centres
    (VG-COEF-CENTRE); centres: (K, 3), or None for the world's origin (P as it is). Linear in P,
    so a pattern's rate dP/dt goes through it too.

    Pattern k's field A_k (x - c_k) + b_k is A_k x + (b_k - A_k c_k), and since
    Phi(c) w = A(w) c + b(w), the new translation columns are 2 b_k - Phi(c_k) P_k.
    """
    if centres is None:
        return P
    b = P[..., :3]
    shift = (basis_matrix(centres) * P[..., None, :]).sum(-1)  # Phi(c_k) P_k: [..., K, 3]
    return torch.cat([2 * b - shift, P[..., 3:]], dim=-1)


def masked(w, mask):
    """w (..., 12) with the columns outside `mask` (cfg.mask or cfg.acc_mask) set to exactly
    zero (identity when mask is None). Unchecked."""
    if mask is None:
        return w
    mask = torch.as_tensor(np.asarray(mask, dtype=bool), device=w.device)
    return w * mask.to(w.dtype)


def rigid_velocity_patterns(B, t, max_time):
    """P(t) of rigid bodies (VG-COEF-RIGID): B (K, 3 + 3 n) rows (omega, c at the n = 2 or 3
    knots evenly spaced over [0, max_time]); t: a tensor that broadcasts against (K, 3), e.g.
    (S, 1, 1) -> (..., K, 12).

    Pattern k is v = omega x (x - c(t)) + c'(t), c(t) the polynomial through its knots:
    translation columns c'(t) - omega x c(t), rotation columns omega, the rest zero.
    """
    omega, c, c_dot, _ = _rigid_centre(B, t, max_time)
    return _rigid_columns(c_dot - torch.linalg.cross(omega, c), omega)


def rigid_velocity_patterns_jet(B, t, max_time):
    """(P, dP/dt) of `rigid_velocity_patterns`, both (..., K, 12): dP/dt has translation
    columns c''(t) - omega x c'(t) and zero elsewhere (the spin is constant)."""
    omega, c, c_dot, c_ddot = _rigid_centre(B, t, max_time)
    P = _rigid_columns(c_dot - torch.linalg.cross(omega, c), omega)
    return P, _rigid_columns(c_ddot - torch.linalg.cross(omega, c_dot), torch.zeros_like(omega))


def harmonic_velocity_patterns(C, omega, t):
    """P(t) of oscillators (VG-COEF-HARM): C (3, K, 12) rows (a, b, c) per pattern, omega (1,)
    their shared frequency; t: a tensor that broadcasts against (K, 1), e.g. (S, 1, 1) ->
    (..., K, 12), P = a + b cos(Omega t) + c sin(Omega t). The forward pass (trajectories,
    rendering) builds no rate: that is `harmonic_velocity_patterns_jet`'s."""
    (a, b, c), cos, sin = C.unbind(0), *_phase(omega, t)
    return a + b * cos + c * sin


def harmonic_velocity_patterns_jet(C, omega, t):
    """(P, dP/dt) of `harmonic_velocity_patterns`, both (..., K, 12):
    dP/dt = Omega (c cos(Omega t) - b sin(Omega t))."""
    (a, b, c), cos, sin = C.unbind(0), *_phase(omega, t)
    return a + b * cos + c * sin, omega * (c * cos - b * sin)


def _phase(omega, t):
    """(cos(Omega t), sin(Omega t)) of VG-COEF-HARM, shared by the patterns and their jet."""
    theta = omega * t
    return torch.cos(theta), torch.sin(theta)


def _rigid_centre(B, t, max_time):
    """(omega, c(t), c'(t), c''(t)) of B's rows, each (..., K, 3), from its knots (VG-COEF-RIGID)."""
    omega, *knots = B.split(3, dim=-1)  # [K, 3] each
    c = c_dot = c_ddot = 0.0
    for knot, (l, dl, ddl) in zip(knots, _lagrange(t, max_time, len(knots))):
        c, c_dot, c_ddot = c + knot * l, c_dot + knot * dl, c_ddot + knot * ddl
    return omega.expand_as(c), c, c_dot.expand_as(c), c_ddot


def _rigid_columns(translation, rotation):
    """[translation | rotation | 0 (stretch) | 0 (shear)] (..., 12) from two (..., 3) blocks."""
    return torch.cat([translation, rotation, translation.new_zeros(translation.shape[:-1] + (6,))], dim=-1)


def _lagrange(t, max_time, n):
    """[(l_i(t), l_i'(t), l_i''(t))] of the Lagrange basis of the n (2 or 3) knots evenly spaced
    over [0, max_time]; t a tensor, derivatives that do not depend on t as floats."""
    nodes = [max_time * i / (n - 1) for i in range(n)]
    out = []
    for i, node in enumerate(nodes):
        others = nodes[:i] + nodes[i + 1:]
        d = math.prod(node - o for o in others)
        if n == 2:
            out.append(((t - others[0]) / d, 1.0 / d, 0.0))
        else:
            a, b = others
            out.append(((t - a) * (t - b) / d, (2 * t - a - b) / d, 2.0 / d))
    return out
