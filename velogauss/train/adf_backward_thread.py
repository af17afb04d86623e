"""The ADF's branch of a training step's backward in a thread of its own, beside the rest of it.

A training step's backward reaches the motion through the state at t, x = x* + Δx (VG-ADF-
COMPOSE): the ADF's branch Δx = F(γ(x0), γ(t), z) (its MLP: matrix products, compute-bound)
and the integration's branch x*(t) (VG-TRAJ: hundreds of small operations) both end at the
canonical means x0 and the code z, and neither needs the other. torch's autograd engine runs
a backward on the thread that called it, so the two branches would run one after the other on
one core while the other is idle or finishing the auxiliary losses (velogauss.train.aux_worker).
`adf_evaluation(spec)` gives `velogauss.model.motion.gaussians_at` an evaluation of the ADF's
residual (its `adf` argument) that hands the ADF's branch to a thread of its own, so that the
integration's runs meanwhile.

How: the ADF is evaluated on detached copies of x0 and z (its own small graph, an
`AdfBackwardJob`), and two autograd Functions stand in for it in the step's graph.
`StartAdfBackward` sits between its output and the composition; the engine runs it as soon as
the composition's gradient arrives (nodes run latest-created first, and it is created after
the integration), and it submits the ADF's backward (`torch.autograd.grad` onto the copies and
the ADF's weights) to the thread. `JoinAdfBackward` sits on x0, z and the weights, created
before the integration, so the engine reaches it only after the integration's branch: it
waits for the thread and passes the gradients on.

The numbers are those of the single backward, to the last bit: the ADF's graph is the same
operations on the same values; x0 and z each receive exactly two sums, the ADF's and the
integration's, whose order does not change a sum of two; the code network's contributions
still come after both (tests/app/test_adf_backward_thread.py). That needs an integration that
reads x0 once, as the affine velocity's does, so `adf_evaluation` offers the thread there only.
"""

import concurrent.futures
import functools

import torch

from velogauss.model.motion import inline_adf
from velogauss_fast.motion.deform import adf_residual


def adf_evaluation(spec):
    """The `adf` argument of `velogauss.model.motion.gaussians_at` that runs the ADF's backward
    in the thread (`start_in_thread`) for the MotionSpec `spec`, or None (inline) where that
    would change the numbers: any velocity but the affine one, whose integration reads x0 once
    (or nothing to overlap: no ADF, or scheme "adf-step", which has no integration from t = 0)."""
    overlaps = spec.adf and spec.scheme == "integrate" and spec.velocity == "affine"
    return start_in_thread if overlaps else None


def start_in_thread(params, x0, t, z, cfg):
    """The ADF's residual `adf_residual(params, x0, t, z, cfg)` with its backward in the
    process's ADF thread: called before the integration's branch, it returns a function giving
    (dx (N, 3), dq (N, 4), ds (N, 3)) in the step's graph, to call after it (see the module
    docstring); x0 (N, 3), z (N, L) as `adf_residual`'s. Inline (`inline_adf`) where no backward
    will reach the ADF's inputs."""
    if not (torch.is_grad_enabled() and (x0.requires_grad or z.requires_grad)):
        return inline_adf(params, x0, t, z, cfg)
    return ThreadedAdfResidual(params, x0, t, z, cfg, _executor()).value


class ThreadedAdfResidual:
    """The ADF's residual in the step's graph, its backward in `thread` (`start_in_thread`).

    The autograd Functions hold the `AdfBackwardJob`, not this handle: the handle holds the
    token, whose graph node holds the job, so no reference cycle keeps a step's graph alive
    after its backward until Python's cyclic collector runs.
    """

    def __init__(self, params, x0, t, z, cfg, thread):
        self._job = AdfBackwardJob(params, x0, t, z, cfg, thread)
        self._token = JoinAdfBackward.apply(self._job, *self._job.inputs)

    def value(self):
        """(dx (N, 3), dq (N, 4), ds (N, 3)), as `adf_residual` returns them, in the step's graph."""
        return StartAdfBackward.apply(self._job, self._token)


class AdfBackwardJob:
    """The ADF's own graph on detached copies of x0 and z, and its backward in `thread`."""

    def __init__(self, params, x0, t, z, cfg, thread):
        self.thread, self.future = thread, None
        weights = [w for pair in params["adf"] for w in pair]
        self.inputs = [x0, z] + weights
        self.wanted = [v.requires_grad for v in self.inputs]
        x0_own, z_own = (v.detach().requires_grad_(v.requires_grad) for v in (x0, z))
        self.leaves = [x0_own, z_own] + weights
        with torch.enable_grad():
            self.out = adf_residual(params, x0_own, t, z_own, cfg)

    def start_backward(self, grads):
        """Submit the ADF's backward for the gradients `grads` of (dx, dq, ds)."""
        leaves = [v for v, want in zip(self.leaves, self.wanted) if want]
        self.future = self.thread.submit(torch.autograd.grad, self.out, leaves, grads, allow_unused=True)

    def join_backward(self):
        """The gradients of (x0, z, weights...) once the thread has them (None where not wanted)."""
        found = iter(self.future.result())
        self.future = self.out = self.leaves = self.inputs = None  # the graph's last use
        return [next(found) if want else None for want in self.wanted]


class JoinAdfBackward(torch.autograd.Function):
    """A token in the step's graph on the ADF's inputs; its backward waits for the thread."""

    @staticmethod
    def forward(ctx, job, *inputs):
        ctx.job = job
        return inputs[0].new_zeros(())

    @staticmethod
    def backward(ctx, _):
        return (None, *ctx.job.join_backward())


class StartAdfBackward(torch.autograd.Function):
    """The ADF's output in the step's graph; its backward starts the thread's."""

    @staticmethod
    def forward(ctx, job, token):
        ctx.job = job
        ctx.token = (token.dtype, token.device)
        return tuple(o.detach() for o in job.out)

    @staticmethod
    def backward(ctx, *grads):
        ctx.job.start_backward(grads)
        dtype, device = ctx.token
        return None, torch.zeros((), dtype=dtype, device=device)


@functools.cache
def _executor():
    """The process's one thread for the ADF's backward (steps run one at a time)."""
    return concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="velogauss-adf")
