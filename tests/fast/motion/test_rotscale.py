"""velogauss_fast.motion.rotscale: VG-ROTSCALE (q_dot, d log s / dt) against velogauss_ref
and analytic cases."""

import math

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

from tests.fast.motion.cases import DEVICE_SETTINGS, check_agreement, check_float32, gradcheck_fn
from velogauss_fast.motion.rotscale import rotscale_rates
from velogauss_ref.motion import rotscale as ref


def _quats(rng, n):
    q = rng.standard_normal((n, 4))
    return q * rng.uniform(0.3, 3.0, (n, 1))  # any norm: the rates must not assume unit q


@pytest.mark.spec("VG-ROTSCALE")
@DEVICE_SETTINGS
@given(seed=st.integers(0, 2**32 - 1), n=st.sampled_from([0, 1, 8]))
def test_reference_vs_fast(device, seed, n):
    rng = np.random.default_rng(seed)
    args = (_quats(rng, n), rng.standard_normal((n, 12)))
    check_agreement(ref.rotscale_rates, rotscale_rates, args, diff=(0, 1), device=device, seed=seed)
    check_float32(ref.rotscale_rates, rotscale_rates, args, device)


@pytest.mark.spec("VG-ROTSCALE")
def test_analytic_cases(device):
    def rates(q, w):
        return rotscale_rates(torch.tensor(q, dtype=torch.float64, device=device)[None],
                              torch.tensor(w, dtype=torch.float64, device=device)[None])

    w = np.zeros(12)
    w[3:6] = [0.2, -0.5, 1.5]  # pure spin: rigid, scales constant, q_dot = 1/2 (0, omega) q
    q_dot, ls_dot = rates([1.0, 0, 0, 0], w)
    np.testing.assert_allclose(q_dot.cpu().numpy()[0], [0, 0.1, -0.25, 0.75], atol=1e-15)
    assert float(ls_dot.abs().max()) < 1e-15

    w = np.zeros(12)
    w[6:9] = [0.3, -0.2, 0.7]  # pure stretch along the world axes
    _, ls_dot = rates([1.0, 0, 0, 0], w)
    np.testing.assert_allclose(ls_dot.cpu().numpy()[0], [0.3, -0.2, 0.7], atol=1e-15)
    # Rotated 90 degrees about z, the Gaussian's first axis lies along world y, its second along -x.
    c = math.sqrt(0.5)
    _, ls_dot = rates([c, 0, 0, c], w)
    np.testing.assert_allclose(ls_dot.cpu().numpy()[0], [-0.2, 0.3, 0.7], atol=1e-15)

    w = np.zeros(12)
    w[9] = 0.4  # shear dv_x/dy = dv_y/dx = 0.4: zero along the world axes, +-0.4 along the diagonals
    _, ls_dot = rates([1.0, 0, 0, 0], w)
    assert float(ls_dot.abs().max()) < 1e-15
    s, t = math.cos(math.pi / 8), math.sin(math.pi / 8)  # 45 degrees about z
    _, ls_dot = rates([s, 0, 0, t], w)
    np.testing.assert_allclose(ls_dot.cpu().numpy()[0], [0.4, -0.4, 0.0], atol=1e-15)


@pytest.mark.spec("VG-ROTSCALE")
def test_zero_quaternion_has_identity_frame(device):
    w = torch.tensor(np.random.default_rng(0).standard_normal((1, 12)), device=device)
    q_dot, ls_dot = rotscale_rates(torch.zeros(1, 4, dtype=torch.float64, device=device), w)
    assert float(q_dot.abs().max()) == 0.0
    torch.testing.assert_close(ls_dot, w[:, 6:9], rtol=0, atol=1e-15)


@pytest.mark.spec("VG-ROTSCALE")
def test_gradcheck(device):
    rng = np.random.default_rng(0)
    gradcheck_fn(rotscale_rates, (_quats(rng, 3), rng.standard_normal((3, 12))), diff=(0, 1), device=device)


@pytest.mark.spec("VG-ROTSCALE")
def test_rejects_bad_input():
    with pytest.raises(ValueError, match="^q"):
        rotscale_rates(torch.zeros(3, 3), torch.zeros(3, 12))
    with pytest.raises(ValueError, match="^w"):
        rotscale_rates(torch.zeros(3, 4), torch.zeros(2, 12))
    with pytest.raises(ValueError, match="^w"):
        rotscale_rates(torch.zeros(1, 4), torch.zeros(1, 12, dtype=torch.int64))
