"""velogauss_ref.motion.code: VG-CODE, the material physics code z = E(gamma(x0))."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tests.ref.gradcheck import check_grads_fd
from tests.ref.motion.cases import FD_STEP, flat_params, random_params, small_cfg
from velogauss_ref.motion.code import physics_code

seeds = st.integers(0, 2**32 - 1)
positions = hnp.arrays(np.float64, (4, 3), elements=st.floats(-1.5, 1.5))


@pytest.mark.spec("VG-CODE")
def test_code_of_a_hand_built_encoder():
    # E = one silu hidden layer and a linear output, on gamma with one frequency, written
    # out with plain NumPy.
    cfg = small_cfg(n_freqs_x=1)
    rng = np.random.default_rng(0)
    W0, b0 = rng.standard_normal((9, 5)), rng.standard_normal(5)
    W1, b1 = rng.standard_normal((5, cfg.code_dim)), rng.standard_normal(cfg.code_dim)
    params = {**random_params(0, cfg), "code": [(W0, b0), (W1, b1)]}
    x0 = rng.uniform(-1, 1, (4, 3))
    gamma = np.concatenate([x0, np.sin(np.pi * x0), np.cos(np.pi * x0)], axis=1)
    u = gamma @ W0 + b0
    expected = (u / (1 + np.exp(-u))) @ W1 + b1
    np.testing.assert_allclose(physics_code(params, x0, cfg), expected, rtol=1e-12, atol=1e-12)


@pytest.mark.spec("VG-CODE")
@given(seeds, positions)
def test_code_is_a_property_of_each_position_alone(seed, x0):
    # Row n of z depends on x0[n] only: reordering or duplicating particles moves their codes.
    cfg = small_cfg()
    params = random_params(seed, cfg)
    z = physics_code(params, x0, cfg)
    assert z.shape == (4, cfg.code_dim)
    order = np.array([2, 0, 3, 1, 2])
    np.testing.assert_allclose(physics_code(params, x0[order], cfg), z[order], rtol=0, atol=1e-14)


@pytest.mark.spec("VG-CODE")
@given(seeds, positions, st.integers(0, 3))
def test_physics_code_gradient(seed, x0, n_freqs_x):
    cfg = small_cfg(n_freqs_x=n_freqs_x)
    theta, unflatten = flat_params(random_params(seed, cfg))
    check_grads_fd(lambda theta, x0: physics_code(unflatten(theta), x0, cfg), (theta, x0), (0, 1),
                   np.random.default_rng(seed), step=FD_STEP)


@pytest.mark.parametrize("x0", [np.zeros((3, 2)), np.full((3, 3), np.nan), np.zeros(3)])
def test_bad_input_names_the_argument(x0):
    cfg = small_cfg()
    with pytest.raises(ValueError, match="^x0:"):
        physics_code(random_params(0, cfg), x0, cfg)
