"""Hard cases of the torch motion model and physics residuals, float32 and float64, forward
and backward: far extrapolation in time, huge velocities, zero quaternions, tiny and huge
scales, empty particle sets. Each must give finite values and finite gradients (and, where
the answer is known, the right one)."""

import math

import numpy as np
import pytest
import torch

from tests.fast.motion.cases import (RIGID_MASK, constant_coefficient_params, leaves, random_params, small_cfg,
                                     to_torch)
from velogauss_fast.motion.code import physics_code
from velogauss_fast.motion.coefficients import coefficients
from velogauss_fast.motion.deform import adf_residual, compose_state
from velogauss_fast.motion.rotscale import rotscale_rates
from velogauss_fast.motion.trajectory import base_state
from velogauss_fast.motion.velocity import velocity_field
from velogauss_fast.physics.acceleration import acceleration_field
from velogauss_fast.physics.residuals import divergence, physics_residuals, transport_residual

DTYPES = [torch.float32, torch.float64]


def _finite_forward_backward(outputs, wrt):
    """Assert every output is finite, then that d(sum of outputs)/d(wrt) exists and is finite."""
    outputs = outputs if isinstance(outputs, tuple) else (outputs,)
    for k, o in enumerate(outputs):
        assert bool(torch.isfinite(o).all()), f"output {k} not finite"
    total = sum(o.sum() for o in outputs)
    # Outputs of one test share subgraphs (the codes z feed several calls): keep them for the next.
    grads = torch.autograd.grad(total, wrt, allow_unused=True, retain_graph=True)
    for k, g in enumerate(grads):
        assert g is None or bool(torch.isfinite(g).all()), f"gradient {k} not finite"


def _setup(dtype, device, n, cfg, seed=0, params=None, scale=None):
    rng = np.random.default_rng(seed)
    params = to_torch(params if params is not None else random_params(seed, cfg), dtype, device, requires_grad=True)

    def tensor(a):
        return torch.tensor(a, dtype=dtype, device=device, requires_grad=True)

    x0 = tensor(rng.uniform(-1, 1, (n, 3)))
    q0 = tensor(rng.standard_normal((n, 4)))
    s0 = tensor(np.full((n, 3), scale) if scale is not None else rng.uniform(0.01, 0.1, (n, 3)))
    return params, x0, q0, s0


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("t", [-5.0, 20.0])
def test_far_times_everything_finite(device, dtype, t):
    # Rigid mask for the integration: a rigid motion keeps |x| within |x0| + integral |b| and
    # s constant, so any finite parameters give a finite state however far t is. (With
    # stretch, exp(integral of the rate) can overflow legitimately.)
    cfg = small_cfg(mask=RIGID_MASK)
    params, x0, q0, s0 = _setup(dtype, device, 5, cfg)
    z = physics_code(params, x0, cfg)
    wrt = leaves(params) + [x0, q0, s0]
    _finite_forward_backward(base_state(params, x0, q0, s0, z, t, 0.1, "rk2", cfg), wrt)
    full = small_cfg()
    params, x, _, _ = _setup(dtype, device, 5, full, seed=1)
    z = physics_code(params, x, full)
    wrt = leaves(params) + [x]
    for out in (coefficients(params, t, z, full), velocity_field(params, x, t, full), adf_residual(params, x, t, z, full),
                acceleration_field(params, x, t, full), transport_residual(params, x, t, full),
                divergence(params, x, t, full), physics_residuals(params, x, t, full)):
        _finite_forward_backward(out, wrt)


@pytest.mark.parametrize("dtype", DTYPES)
def test_huge_velocities_small_step(device, dtype):
    # Coefficients ~1e3: translation 1e3, spin 1e3 rad per unit time. With h = 1e-4 the
    # step turns 0.1 rad, well inside RK4's stability region; t = 0.02 is 20 rad.
    w = np.zeros(12)
    w[0:3] = [1e3, -2e3, 5e2]
    w[3:6] = [0.0, 0.0, 1e3]
    cfg = small_cfg()
    params_np = constant_coefficient_params(0, cfg, w, acc=np.full((3, 12), 1e3))
    params, x0, q0, s0 = _setup(dtype, device, 4, cfg, params=params_np)
    z = physics_code(params, x0, cfg)
    t = 0.02
    x, q, s = base_state(params, x0, q0, s0, z, t, 1e-4, "rk4", cfg)
    _finite_forward_backward((x, q, s), leaves(params) + [x0, q0, s0])
    # Closed form: rotation by 20 rad about z of x0 plus the swept translation,
    # x(t) = R(t) x0 + integral_0^t R(t - u) b du.
    a = 1e3 * t
    c, s_ = math.cos(a), math.sin(a)
    R = torch.tensor([[c, -s_, 0], [s_, c, 0], [0, 0, 1]], dtype=torch.float64)
    b = torch.tensor(w[:3])
    swept = torch.tensor([[s_, -(1 - c), 0], [1 - c, s_, 0], [0, 0, a]], dtype=torch.float64) @ b / 1e3
    expected = x0.detach().cpu().double() @ R.T + swept
    # RK4 phase error ~ (h omega)^5 / 120 per step over 200 steps ~ 2e-5 rad on |x| ~ 3; the
    # float32 rounding of 200 steps of size ~0.2 adds ~1e-5.
    torch.testing.assert_close(x.detach().cpu().double(), expected, rtol=0, atol=2e-4)
    xs = x0.detach().clone().requires_grad_()
    for out in (transport_residual(params, xs, t, cfg), divergence(params, xs, t, cfg), physics_residuals(params, xs, t, cfg)):
        _finite_forward_backward(out, leaves(params) + [xs])


@pytest.mark.parametrize("dtype", DTYPES)
def test_zero_quaternions(device, dtype):
    cfg = small_cfg()
    params, x0, _, s0 = _setup(dtype, device, 3, cfg)
    q0 = torch.zeros(3, 4, dtype=dtype, device=device, requires_grad=True)
    z = physics_code(params, x0, cfg)
    x, q, s = base_state(params, x0, q0, s0, z, 0.5, 0.1, "rk2", cfg)
    # A zero quaternion has zero rate and stays zero: it comes back as the identity.
    assert torch.equal(q, torch.tensor([[1.0, 0, 0, 0]] * 3, dtype=dtype, device=device))
    _finite_forward_backward((x, q, s), leaves(params) + [x0, q0, s0])
    w = torch.randn(3, 12, dtype=dtype, device=device, requires_grad=True)
    _finite_forward_backward(rotscale_rates(q0, w), [q0, w])
    dq = torch.zeros(3, 4, dtype=dtype, device=device, requires_grad=True)
    dx = torch.zeros(3, 3, dtype=dtype, device=device, requires_grad=True)
    out = compose_state(x0, q0, s0, dx, dq, dx)
    assert torch.equal(out[1], torch.tensor([[1.0, 0, 0, 0]] * 3, dtype=dtype, device=device))
    _finite_forward_backward(out, [x0, q0, s0, dx, dq])


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("scale", [1e-8, 1e4])
def test_tiny_and_huge_scales(device, dtype, scale):
    cfg = small_cfg()
    params, x0, q0, s0 = _setup(dtype, device, 4, cfg, scale=scale)
    z = physics_code(params, x0, cfg)
    x, q, s = base_state(params, x0, q0, s0, z, 0.7, 0.1, "rk4", cfg)
    _finite_forward_backward((x, q, s), leaves(params) + [x0, q0, s0])
    # Scales evolve multiplicatively (in log space): relative change independent of the scale.
    _, _, s_unit = base_state(params, x0, q0, torch.ones_like(s0), z, 0.7, 0.1, "rk4", cfg)
    rtol = 1e-5 if dtype == torch.float32 else 1e-12
    torch.testing.assert_close(s / scale, s_unit, rtol=rtol, atol=0)
    dx, dq, ds = adf_residual(params, x0, 0.7, z, cfg)
    _finite_forward_backward(compose_state(x, q, s, dx, dq, ds), leaves(params) + [x0, q0, s0])


@pytest.mark.parametrize("dtype", DTYPES)
def test_no_particles(device, dtype):
    cfg = small_cfg()
    params, x0, q0, s0 = _setup(dtype, device, 0, cfg)
    z = physics_code(params, x0, cfg)
    assert z.shape == (0, cfg.code_dim)
    wrt = leaves(params) + [x0, q0, s0]
    outs = [coefficients(params, 0.5, z, cfg), velocity_field(params, x0, 0.5, cfg),
            base_state(params, x0, q0, s0, z, 0.5, 0.1, "rk2", cfg), adf_residual(params, x0, 0.5, z, cfg),
            acceleration_field(params, x0, 0.5, cfg), transport_residual(params, x0, 0.5, cfg),
            divergence(params, x0, 0.5, cfg), physics_residuals(params, x0, 0.5, cfg),
            rotscale_rates(q0, coefficients(params, 0.5, z, cfg))]
    shapes = [(0, 12), (0, 3), ((0, 3), (0, 4), (0, 3)), ((0, 3), (0, 4), (0, 3)), (0, 3), (0, 3), (0,),
              ((0, 3), (0,)), ((0, 4), (0, 3))]
    for out, shape in zip(outs, shapes):
        got = tuple(o.shape for o in out) if isinstance(out, tuple) else out.shape
        assert got == shape
        _finite_forward_backward(out, wrt)
