"""velogauss.train.adf_backward_thread: the ADF's backward in a thread of its own gives the
single backward's gradients to the last bit."""

import gc
import weakref

import numpy as np
import pytest
import torch

from velogauss.config import ModelConfig
from velogauss.model.motion import MotionParameters, gaussians_at
from velogauss.model.spec import resolve_motion_spec
from velogauss.train import adf_backward_thread
from velogauss.train.adf_backward_thread import AdfBackwardJob, adf_evaluation

# Rotation and stretch move q and s too, so every output of the ADF and of the integration
# carries a gradient; the rigid and oscillating patterns have time parameters of their own.
SCENES = {"mlp": dict(effects=("translation", "rotation", "stretch"), incompressible=False),
          "rigid": dict(effects=("translation", "rotation"), incompressible=False, patterns="rigid"),
          "harmonic": dict(effects=("stretch", "oscillation"), incompressible=False, patterns="harmonic"),
          "translation": dict(effects=("translation",), incompressible=False, patterns="mlp")}
SMALL = dict(n_freqs_x=2, n_freqs_adf_x=2, n_freqs_adf_t=1, code_dim=4, n_patterns=4, hidden=16, depth=2)


def _setup(ablation, dtype, frozen=(), canonical_grad=True, patterns="mlp", n=64):
    spec = resolve_motion_spec(ModelConfig(ablation=ablation, **SCENES[patterns], **SMALL), None, 0.75)
    motion = MotionParameters(spec, np.random.default_rng(0)).to(dtype)
    g = torch.Generator().manual_seed(1)
    with torch.no_grad():  # away from the still start (the ADF's last layer is zero there)
        for p in motion.parameters():
            p.add_(0.3 * torch.randn(p.shape, generator=g, dtype=dtype))
    for name in frozen:
        getattr(motion, name).requires_grad_(False)
    q = torch.randn(n, 4, generator=g, dtype=dtype)
    canonical = [torch.rand(n, 3, generator=g, dtype=dtype) * 2 - 1, q / q.norm(dim=1, keepdim=True),
                 torch.rand(n, 3, generator=g, dtype=dtype) * 0.2 + 0.05]
    for c in canonical:
        c.requires_grad_(canonical_grad)
    weights = [torch.randn(n, k, generator=g, dtype=dtype) for k in (3, 4, 3, 3)]
    return spec, motion, canonical, weights


def _gradients(spec, motion, canonical, weights, adf):
    leaves = [p for p in motion.parameters() if p.requires_grad] + [c for c in canonical if c.requires_grad]
    out = gaussians_at(motion.params(), spec, *canonical, 0.9, adf=adf)
    loss = sum((o * w).sum() for o, w in zip(out, weights)) + (out[0] - out[3]).pow(2).sum()
    # allow_unused: the acceleration polynomial is a physics-loss parameter, not the motion's
    return [v.detach() for v in out], torch.autograd.grad(loss, leaves, allow_unused=True)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("patterns, frozen, canonical_grad", [
    ("mlp", (), True),
    ("rigid", (), True),
    ("harmonic", (), True),
    ("translation", (), True),
    ("mlp", (), False),  # train.motion_only: the canonical Gaussians frozen
    ("mlp", ("code",), True),  # z needs no gradient
    ("mlp", ("adf",), True),  # the ADF's weights frozen: only x0 and z get its gradient
])
def test_the_adf_in_its_thread_gives_the_single_backwards_numbers(dtype, patterns, frozen, canonical_grad):
    spec, motion, canonical, weights = _setup("full", dtype, frozen, canonical_grad, patterns)
    assert spec.adf and spec.pattern_form == ("mlp" if patterns == "translation" else patterns)
    assert adf_evaluation(spec) is adf_backward_thread.start_in_thread
    out_one, grads_one = _gradients(spec, motion, canonical, weights, adf=None)
    out_two, grads_two = _gradients(spec, motion, canonical, weights, adf=adf_evaluation(spec))
    assert len(grads_one) == len(grads_two) > 0
    assert [g is None for g in grads_one] == [g is None for g in grads_two]
    for a, b in zip(out_one + list(grads_one), out_two + list(grads_two)):
        if a is not None:
            assert a.dtype == b.dtype == dtype
            assert torch.equal(a, b)
    assert all(bool(g.abs().sum() > 0) for g in grads_two if g is not None)


@pytest.mark.parametrize("ablation, grad", [("full", False), ("no-pds", True), ("deform-only", True)])
def test_the_adf_thread_is_used_only_beside_an_affine_integration_and_before_a_backward(
        monkeypatch, ablation, grad):
    """No backward, or no integration that reads x0 once (the MLP velocity's integrator reads
    it at every stage, deform-only has none): the ADF runs inline, as without the thread."""
    spec, motion, canonical, _ = _setup(ablation, torch.float32)
    assert (adf_evaluation(spec) is None) == (ablation != "full")
    monkeypatch.setattr(adf_backward_thread, "AdfBackwardJob", None)  # any job would raise
    with torch.set_grad_enabled(grad):
        threaded = gaussians_at(motion.params(), spec, *canonical, 0.9, adf=adf_evaluation(spec))
        plain = gaussians_at(motion.params(), spec, *canonical, 0.9)
    for a, b in zip(threaded, plain):
        assert torch.equal(a, b)


def test_an_error_in_the_thread_reaches_the_backward(monkeypatch):
    spec, motion, canonical, weights = _setup("full", torch.float32)
    out = gaussians_at(motion.params(), spec, *canonical, 0.9, adf=adf_evaluation(spec))

    def fails(*args, **kwargs):
        raise RuntimeError("boom in the ADF's thread")

    monkeypatch.setattr(torch.autograd, "grad", fails)
    with pytest.raises(RuntimeError, match="boom in the ADF's thread"):
        sum((o * w).sum() for o, w in zip(out, weights)).backward()


def test_a_steps_graph_is_freed_by_its_last_reference_not_by_the_cyclic_collector(monkeypatch):
    """No reference cycle through the autograd Functions: a cycle would keep every step's
    graph alive until Python's cyclic collector runs."""
    jobs = []
    made = AdfBackwardJob.__init__
    monkeypatch.setattr(AdfBackwardJob, "__init__", lambda self, *a: (jobs.append(weakref.ref(self)), made(self, *a))[1])
    spec, motion, canonical, weights = _setup("full", torch.float32)
    gc.disable()
    try:
        out = gaussians_at(motion.params(), spec, *canonical, 0.9, adf=adf_evaluation(spec))
        sum((o * w).sum() for o, w in zip(out, weights)).backward()
        assert len(jobs) == 1 and jobs[0]() is not None  # the outputs' graph still holds it
        del out
        assert jobs[0]() is None
    finally:
        gc.enable()
