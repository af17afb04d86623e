"""velogauss_fast.checks: the structural check reads no data, the finiteness check one flag."""

import numpy as np
import pytest
import torch
from torch.func import jvp, vmap

from velogauss_fast.checks import check_array, check_finite


@pytest.mark.parametrize("x, shape, message", [
    (np.zeros((2, 3)), (None, 3), "^x: expected a torch.Tensor"),
    (torch.zeros(2, 4), (None, 3), r"^x: expected shape \(N, 3\), got \(2, 4\)"),
    (torch.zeros(2, 3, dtype=torch.int64), (None, 3), "^x: expected a floating-point tensor"),
])
def test_check_array_refuses_the_structure_naming_the_argument(x, shape, message):
    with pytest.raises(ValueError, match=message):
        check_array("x", x, shape)


def test_check_array_reads_no_values():
    # A NaN passes (finiteness is the doors' check), and the check runs inside vmap and jvp,
    # where reading a value (bool(tensor)) raises: it looks at shape and dtype alone.
    x = torch.tensor([[0.0, float("nan"), 1.0]])
    assert check_array("x", x, (None, 3)) is x
    vmap(lambda row: check_array("x", row, (3,)))(torch.zeros(4, 3))
    jvp(lambda y: check_array("x", y, (None, 3)), (torch.zeros(2, 3),), (torch.ones(2, 3),))


@pytest.mark.parametrize("dtype", [torch.float32, torch.bfloat16], ids=["numpy", "torch"])
def test_check_finite_names_the_first_bad_tensor_with_one_host_read(monkeypatch, dtype):
    good, nan, inf = torch.zeros(3), torch.tensor([0.0, float("nan"), 1.0]), torch.full((2, 2), float("inf"))
    good, nan, inf = good.to(dtype), nan.to(dtype), inf.to(dtype)
    reads = []
    bool_ = torch.Tensor.__bool__
    monkeypatch.setattr(torch.Tensor, "__bool__", lambda self: reads.append(1) or bool_(self))
    check_finite(a=good, b=good.double(), c=torch.zeros(0))
    # One device sync however many tensors; CPU tensors NumPy can hold are read by NumPy, with none.
    assert len(reads) == (0 if dtype == torch.float32 else 1)
    with pytest.raises(ValueError, match=r"^b: contains 1 non-finite value\(s\)"):
        check_finite(a=good, b=nan, c=inf)
    with pytest.raises(ValueError, match=r"^c: contains 4 non-finite value\(s\)"):
        check_finite(a=good, c=inf)
