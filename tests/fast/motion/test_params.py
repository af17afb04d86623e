"""velogauss_fast.motion.params: the reference's parameter dict as tensors."""

import numpy as np
import pytest
import torch

from tests.fast.motion.cases import leaves, random_params, small_cfg
from velogauss_fast.motion.params import params_to_torch


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_same_structure_and_values(device, dtype):
    params = random_params(0, small_cfg())
    out = params_to_torch(params, dtype, device, requires_grad=True)
    assert out.keys() == params.keys()
    for key in params:
        # Containers keep their type (list of (W, b) tuples); array leaves become tensors.
        if isinstance(params[key], list):
            assert type(out[key]) is list
            assert all(type(a) is type(b) and len(a) == len(b) for a, b in zip(out[key], params[key]))
        else:
            assert isinstance(out[key], torch.Tensor)
    for t, a in zip(leaves(out), leaves(params)):
        assert t.dtype == dtype and t.device.type == torch.device(device).type
        assert t.is_leaf and t.requires_grad
        np.testing.assert_allclose(t.detach().cpu().numpy(), a, rtol=1e-7 if dtype == torch.float32 else 0)


def test_no_grad_by_default_and_no_shared_memory():
    params = random_params(0, small_cfg())
    out = params_to_torch(params, torch.float64, "cpu")
    assert not any(t.requires_grad for t in leaves(out))
    leaves(out)[0].zero_()
    assert np.any(leaves(params)[0] != 0)


def test_rejects_bad_input():
    params = random_params(0, small_cfg())
    params["acc"] = np.full_like(params["acc"], np.nan)
    with pytest.raises(ValueError, match="acc"):
        params_to_torch(params, torch.float64, "cpu")
    with pytest.raises(ValueError, match="dtype"):
        params_to_torch(random_params(0, small_cfg()), torch.int64, "cpu")
