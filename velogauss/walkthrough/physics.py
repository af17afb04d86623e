"""Walkthrough part: acceleration and the two physics residuals (VG-ACC, VG-ACC-RIGID, VG-ACC-HARM,
VG-TRANSPORT, VG-DIV) on a rigid field, a stretching field and a non-physical (random network) field."""

import dataclasses
import functools

import numpy as np

from velogauss_ref.physics.acceleration import acceleration_field, harmonic_patterns, rigid_patterns
from velogauss_ref.motion.velocity import mlp_velocity
from velogauss_ref.physics.residuals import divergence, mlp_residuals, transport_residual
from velogauss.walkthrough.figures import new_figure, save
from velogauss.walkthrough.printing import Section, number, session
from velogauss.walkthrough.setups import (CFG, coefficient_vector, constant_motion_params, learned_motion_params,
                                         mlp_velocity_params)

SPIN = 1.5  # rad per unit time about z
STRETCH = np.array([0.5, 0.25, 0.0])
T = 0.5
POINTS = np.array([[1.0, 0.0, 0.0], [0.0, -0.5, 0.3], [0.5, 0.5, -0.5]])
GRID = 9  # residual maps sample a GRID x GRID slice: the reference differentiates point by point


def fields():
    """The three example fields, name -> motion parameters:
    rigid: v = ω × x about z, with the acceleration set to its centripetal acceleration
      Ω² x = −SPIN² (x, y, 0), which is the stretch pattern (−SPIN², −SPIN², 0);
    stretching: v = diag(STRETCH) x, with the acceleration diag(STRETCH)² x (again stretch);
    random network: learned_motion_params, whose patterns change with t and whose code
      changes with x, with no acceleration.
    """
    return {
        "rigid": constant_motion_params(coefficient_vector(rotation=(0, 0, SPIN)),
                                        alpha=coefficient_vector(stretch=(-SPIN**2, -SPIN**2, 0))),
        "stretching": constant_motion_params(coefficient_vector(stretch=STRETCH),
                                             alpha=coefficient_vector(stretch=STRETCH**2)),
        "random network": learned_motion_params(),
    }


def acceleration_section(figures):
    """VG-ACC: the centripetal acceleration of a rigid spin, against −ω² (x, y, 0)."""
    params = fields()["rigid"]
    return Section(
        "The transport residual below compares the velocity field's own material acceleration "
        "`Dv/Dt` with a modelled acceleration `a`. If `a` were a free network it could match anything "
        "and the constraint would teach nothing; so `a` is built like `v` (the 12 basis fields, mixed "
        "by the same code) with coefficients that are a low-degree polynomial in t per pattern. "
        "Gravity is degree 0; the centripetal acceleration of a spin is the square of its generator, "
        "a stretch-and-shear pattern. The example is a spin at "
        f"{number(SPIN)} rad per unit time about z whose acceleration coefficients are set to "
        "its centripetal acceleration, −ω² (x, y, 0). Scenes whose motion is rigid use the rigid "
        "form of the next section instead of the polynomial.",
        [session({"x": POINTS, "t": T}, "a = acceleration_field(params, x, t, cfg)",
                 {"a": acceleration_field(params, POINTS, T, CFG),
                  "−ω² (x, y, 0)": -SPIN**2 * POINTS * [1, 1, 0]})],
    )


# A body thrown like the default scene's: a spin about z while its centre flies a parabola.
TOSS = {"omega": np.array([0.0, 0.0, 2.0]), "g": np.array([0.0, 0.0, -8.0]), "c0": np.array([-0.5, 0.0, -0.5]),
        "u": np.array([1.0, 0.0, 4.0])}


def rigid_acceleration_section(figures):
    """VG-ACC-RIGID: a spinning, falling body's acceleration, against g + ω × (ω × (x − c(t)))."""
    B = np.concatenate([TOSS[k] for k in ("omega", "g", "c0", "u")])[None, :]
    c = TOSS["c0"] + TOSS["u"] * T + 0.5 * TOSS["g"] * T**2
    by_hand = TOSS["g"] + np.cross(TOSS["omega"], np.cross(TOSS["omega"], POINTS - c))
    cfg = dataclasses.replace(CFG, acc_form="rigid")
    # Every motion pattern is this body, so any mixture of them is too.
    params = {**constant_motion_params(coefficient_vector()), "acc": np.tile(B, (CFG.n_patterns, 1))}
    return Section(
        "For a scene whose motion is rigid (translation, rotation, gravity), each motion pattern is a "
        "rigid body: a constant spin ω and a centre c(t) that moves under a constant acceleration g, "
        "so `a = g + ω × (ω × (x − c(t)))`. Twelve numbers per pattern (ω, g, and the centre and its "
        "velocity at t = 0) replace the polynomial's 36. A point's mixing weights mix the bodies' "
        "numbers, not their accelerations, so every point follows one rigid body at all times, and "
        "gravity and the spin cannot drift with t past the observed window. The example spins at 2 rad per unit "
        "time about z while its centre is thrown up from (−0.5, 0, −0.5) at (1, 0, 4) under g = (0, 0, −8).",
        [session({"B": B, "t": T}, "alpha = rigid_patterns(B, t)  # translation | rotation | stretch | shear",
                 {"alpha": rigid_patterns(B, T)}),
         session({"x": POINTS, "t": T}, "a = acceleration_field(params, x, t, cfg)  # cfg.acc_form = 'rigid'",
                 {"a": acceleration_field(params, POINTS, T, cfg), "g + ω × (ω × (x − c(t)))": by_hand})],
    )


def harmonic_acceleration_section(figures):
    """VG-ACC-HARM: the pulsing cube's acceleration from harmonics 0, 1 and 2 of its frequency."""
    w, L = 3.0 * np.pi, np.log(1.6) * np.array([1.0, -0.5, -0.5])
    Q = np.zeros((5, 1, 12))
    Q[0, 0, 6:9] = Q[3, 0, 6:9] = 0.5 * w * w * L * L  # (1 + cos 2θ) / 2 · ω² L²
    Q[2, 0, 6:9] = -w * w * L  # −sin θ · ω² L
    by_hand = w * w * (np.cos(w * T) ** 2 * L * L - np.sin(w * T) * L) * POINTS
    cfg = dataclasses.replace(CFG, pattern_form="harmonic", acc_form="harmonic")
    params = {**constant_motion_params(coefficient_vector()), "acc": np.tile(Q, (1, CFG.n_patterns, 1)),
              "time": [(np.zeros((3, CFG.n_patterns, 12)), np.array([w]))]}
    return Section(
        "Oscillating patterns bring their own acceleration: harmonics 0, 1 and 2 of the patterns' "
        "frequency, `Q₀ + Σⱼ Q₂ⱼ₋₁ cos(jΩt) + Q₂ⱼ sin(jΩt)`. For `v = L(t) x` the material "
        "acceleration is `(L̇ + L²) x`, whose frequencies are exactly 0, Ω and 2Ω, so the transport "
        "residual asks the velocity to keep oscillating past the window instead of bending it "
        "towards a quadratic in t. The example is the pulsing cube of VG-COEF-HARM, whose "
        "acceleration is `ω² (cos²(ωt) L² − sin(ωt) L) x`.",
        [session({"Q[:, 0, 6:9]": Q[:, 0, 6:9], "omega": np.array([w]), "t": T},
                 "alpha = harmonic_patterns(Q, omega, t)  # stretch columns 6:9",
                 {"alpha[:, 6:9]": harmonic_patterns(Q, np.array([w]), T)[:, 6:9]}),
         session({"x": POINTS, "t": T}, "a = acceleration_field(params, x, t, cfg)  # cfg.acc_form = 'harmonic'",
                 {"a": acceleration_field(params, POINTS, T, cfg), "ω² (cos²(ωt) L² − sin(ωt) L) x": by_hand})],
    )


def transport_section(figures):
    """VG-TRANSPORT: residuals of the three example fields (and of a spin without acceleration); maps."""
    steps = []
    for name, params in fields().items():
        steps += [f"transport_residual(params, x, t, cfg)  # {name}", {"r": transport_residual(params, POINTS, T, CFG)}]
    still = {**fields()["rigid"], "acc": np.zeros_like(fields()["rigid"]["acc"])}
    steps += ["# rigid, but with no acceleration modelled: the residual is the missing centripetal term",
              {"r": transport_residual(still, POINTS, T, CFG)}]
    maps = residual_maps()
    return Section(
        "The momentum constraint (paper eq. 7): following a particle, the velocity changes at the rate "
        "`Dv/Dt = ∂v/∂t + (∇v) v`, and that must be the modelled acceleration. The reference takes "
        "every derivative with autograd, through the whole field including the code's dependence on "
        "x. A rigid spin and a uniform stretch satisfy it exactly with their acceleration; a field "
        "made of random networks does not, and training's physics loss pushes on exactly that.",
        [session({"x": POINTS, "t": T}, *steps),
         _maps_figure(figures, "transport-residual", {k: np.linalg.norm(v[0], axis=-1) for k, v in maps.items()},
                      "|r|", "magma",
                      "|transport_residual| on the slice z = 0 at t = 0.5, one colour scale: zero for the rigid "
                      "and the stretching field (each with its true acceleration), non-zero everywhere for "
                      "the random network field.")],
    )


def divergence_section(figures):
    """VG-DIV: divergences of the three example fields; maps."""
    steps = []
    for name, params in fields().items():
        steps += [f"divergence(params, x, t, cfg)  # {name}", {"div": divergence(params, POINTS, T, CFG)}]
    maps = residual_maps()
    return Section(
        "Mass conservation of an incompressible material (paper eq. 8): `∇·v = 0`, volume is neither "
        "created nor destroyed. The divergence of an affine field is the trace of A, `w7 + w8 + w9`. "
        "The two residuals test different things: the stretching field is perfectly consistent "
        f"with its acceleration but grows volume at the rate {number(STRETCH.sum())}, so it only fits "
        "a scene declared compressible (where the divergence term is dropped).",
        [session({"x": POINTS, "t": T}, *steps),
         _maps_figure(figures, "divergence", {k: v[1] for k, v in maps.items()}, "∇·v", "coolwarm",
                      "divergence on the slice z = 0 at t = 0.5, one symmetric colour scale: 0 for the rigid "
                      f"spin, {number(STRETCH.sum())} everywhere for the stretch, varying for the random network "
                      "field.")],
    )


@functools.cache
def residual_maps():
    """name -> (r (GRID, GRID, 3), div (GRID, GRID)) of each example field on the slice z = 0, t = T."""
    u = np.linspace(-1, 1, GRID)
    gx, gy = np.meshgrid(u, u)
    points = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=-1)
    return {name: (transport_residual(params, points, T, CFG).reshape(GRID, GRID, 3),
                   divergence(params, points, T, CFG).reshape(GRID, GRID))
            for name, params in fields().items()}


def _maps_figure(figures, name, maps, label, cmap, caption):
    fig = new_figure(10, 3.4)
    largest = max(np.abs(m).max() for m in maps.values())
    limits = (-largest, largest) if cmap == "coolwarm" else (0, largest)
    for ax, (field, values) in zip(fig.subplots(1, 3), maps.items()):
        shown = ax.imshow(values, origin="lower", extent=(-1.125, 1.125, -1.125, 1.125), cmap=cmap,
                          vmin=limits[0], vmax=limits[1], interpolation="nearest")
        ax.set(title=f"{field}\nlargest magnitude {number(np.abs(values).max())}", xlabel="x", ylabel="y")
    fig.colorbar(shown, ax=fig.axes, shrink=0.8, label=label)
    return save(fig, figures, name, caption)


def mlp_residuals_section(figures):
    """VG-TRANSPORT-MLP: the residuals of the no-pds velocity, against central differences."""
    params, h = mlp_velocity_params(), 1e-5
    v = mlp_velocity(params, POINTS, T, CFG)
    dv_dt = (mlp_velocity(params, POINTS, T + h, CFG) - mlp_velocity(params, POINTS, T - h, CFG)) / (2 * h)
    grad_v = np.stack([(mlp_velocity(params, POINTS + h * e, T, CFG) - mlp_velocity(params, POINTS - h * e, T, CFG))
                       / (2 * h) for e in np.eye(3)], axis=-1)
    r, div = mlp_residuals(params, POINTS, T, CFG, with_divergence=True)
    return Section(
        "Without the PDS the physics losses stay: the same transport residual and divergence, "
        "now of the MLP velocity, with the same acceleration field (zero here). The reference "
        "differentiates the network with autograd, point by point; below, both are recomputed "
        f"from central differences of step {number(h)}, and agree to the digits shown.",
        [session({"x": POINTS, "t": T}, "r, div = mlp_residuals(params, x, t, cfg, with_divergence=True)",
                 {"r": r, "div": div},
                 "# central differences: dv/dt + (grad v) v and trace(grad v)",
                 {"r (differences)": dv_dt + np.einsum("nij,nj->ni", grad_v, v),
                  "div (differences)": np.trace(grad_v, axis1=1, axis2=2)})],
    )


SECTIONS = {"VG-ACC": acceleration_section, "VG-ACC-RIGID": rigid_acceleration_section,
            "VG-ACC-HARM": harmonic_acceleration_section,
            "VG-TRANSPORT": transport_section, "VG-DIV": divergence_section,
            "VG-TRANSPORT-MLP": mlp_residuals_section}
