"""The worker process that computes a training step's auxiliary losses (velogauss.train.aux_losses).

Why a process, not a thread: the auxiliary losses are hundreds of small torch operations, each
holding Python's GIL for its microseconds of Python, and in a thread the main thread's own
small operations waited for it (benchmarks/RESULTS.md, "Toward a 2x step"). A process has a
GIL of its own.

What crosses, per step:
- the motion parameters and the canonical Gaussians (`velogauss.train.aux_losses.Canonical`),
  copied by the main process into shared memory (files mapped by both, unlinked once the
  process has mapped them) before the step, which it changes only after `finish`; the
  process copies them into tensors of its own;
- through a socket: the draws, the step's spec when it changed, and, when a training starts,
  the configuration and the parameters' layout;
- back: the gradients in shared memory, the loss and which gradients exist through the socket.

The process computes what a thread would: `loss_and_gradients`, with the same operations on the same
values and torch's thread count of the main process, so the training is the same to the last
bit (tests/app/test_train.py). One process serves every training of its parent, one step at
a time: `process()` starts it when a training is prepared, as `python -m
velogauss.train.aux_worker` (a fresh interpreter: no locks forked in a held state, and
unlike multiprocessing's spawn it never imports the parent's script, which may have no
`if __name__ == "__main__"` guard). It runs in a session of its own, so Ctrl-C in a terminal
is the training's alone (velogauss.train.loop checkpoints, then stops), and it exits when
its parent's end of the socket closes.
"""

import atexit
import os
import pickle
import socket
import subprocess
import sys
import tempfile
import traceback
from multiprocessing.connection import Connection
from pathlib import Path

import numpy as np
import torch

from velogauss.model.motion import MotionParameters
from velogauss.train import aux_losses

# Rows per Gaussian in the shared buffer of the canonical Gaussians: means 3, quats 4, scales 3.
_ROWS = (3, 4, 3)
_PROCESS = None


def process():
    """The auxiliary losses' worker of this process, started (or restarted, after it ended) here."""
    global _PROCESS
    if _PROCESS is None or not _PROCESS.alive():
        if _PROCESS is None:
            atexit.register(_close)
        _PROCESS = AuxWorker()
    return _PROCESS


def _close():
    if _PROCESS is not None:
        _PROCESS.close()


class AuxWorker:
    """A process computing `velogauss.train.aux_losses.loss_and_gradients` for the steps
    `submit` sends it."""

    def __init__(self):
        ours, theirs = socket.socketpair()
        # The parent's imports; and idle OpenMP threads that sleep, whatever the parent's policy,
        # as spinning ones take the main process's cores (benchmarks/RESULTS.md). Where threads
        # wait changes no number.
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(p or os.getcwd() for p in sys.path),
                   OMP_WAIT_POLICY="PASSIVE")
        with theirs:
            # -P: no working folder before those paths, so that it imports the parent's velogauss.
            self._process = subprocess.Popen([sys.executable, "-P", "-m", __name__, str(theirs.fileno())],
                                             pass_fds=(theirs.fileno(),), env=env, start_new_session=True,
                                             stdin=subprocess.DEVNULL)
        self._conn = Connection(ours.detach())
        self._setup = None  # (motion spec, config, torch threads, dtype) the process holds
        self._spec = None  # the step spec it holds
        self._capacity = 0  # Gaussians its canonical buffer holds
        self._params = self._grads = self._canon = self._moving = None
        self._mapped = []  # files the process maps on its next message: unlinked after its answer
        self._pending = False

    @property
    def pid(self):
        """The worker process's id."""
        return self._process.pid

    def alive(self):
        """Whether the worker process is still running."""
        return self._process.poll() is None

    def close(self):
        """End the process: it exits when its end of the socket closes."""
        self._conn.close()
        self._unlink()
        try:
            self._process.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            self._process.kill()
            self._process.wait()

    def submit(self, motion, canon, cfg, spec, draws):
        """Start `loss_and_gradients` of `draws` for the motion parameters of `motion`
        (velogauss.model.motion.MotionParameters, those requiring a gradient differentiated),
        the `Canonical` canon, config `cfg` and the step's MotionSpec `spec`; returns the
        pending result (`.result()`: what `loss_and_gradients` returns, gradients onto `motion`'s
        parameters)."""
        if self._pending:
            self.receive()  # a step whose result nobody took: its answer comes first
        params = list(motion.parameters())
        extras = {}
        # The patterns' centres are data that training places once, not parameters: sent with the setup.
        centres = tuple(map(tuple, motion.centre.tolist()))
        setup = (motion.spec, cfg, torch.get_num_threads(), params[0].dtype, centres)
        if setup != self._setup:
            numel = sum(p.numel() for p in params)
            self._params, self._grads = (self._shared(numel, params[0].dtype) for _ in range(2))
            extras["setup"] = (motion.spec, cfg, setup[2], self._mapped[-2:], centres)
            self._setup, self._spec, self._capacity = setup, None, 0
        n = canon.means.shape[0]
        if n > self._capacity:
            self._capacity = max(n, 2 * self._capacity)  # densification grows N: few reallocations
            self._canon = self._shared(sum(_ROWS) * self._capacity, canon.means.dtype)
            self._moving = self._shared(self._capacity, torch.bool)
            extras["canon"] = self._mapped[-2:]
        torch.cat([p.detach().reshape(-1) for p in params], out=self._params)
        torch.cat([canon.means.reshape(-1), canon.quats.reshape(-1), canon.scales.reshape(-1)],
                  out=self._canon[:sum(_ROWS) * n])
        self._moving[:n].copy_(canon.moving)
        flags = tuple(p.requires_grad for p in params)
        message = (extras, n, flags, None if spec == self._spec else spec, _arrays(draws))
        try:
            self._conn.send_bytes(pickle.dumps(message, pickle.HIGHEST_PROTOCOL))
        except OSError:
            raise self._ended() from None
        self._spec, self._pending = spec, True
        return _Pending(self, params, flags)

    def gradients(self, params, flags, present):
        """[(parameter, its gradient or None)] of the parameters with a set flag, read from
        the shared gradients (copied: the next step writes there again)."""
        grads = _per_parameter(self._grads, params)
        return [(p, g.clone() if has else None) for p, g, flag, has in zip(params, grads, flags, present) if flag]

    def receive(self):
        """The answer to the last `submit`: (loss, which parameters got a gradient); raises
        what the auxiliary losses raised, with the process's traceback as its cause."""
        try:
            reply = pickle.loads(self._conn.recv_bytes())
        except (EOFError, OSError):
            raise self._ended() from None
        finally:
            self._pending = False
            self._unlink()
        if reply[0] == "error":
            _, exc, text = reply
            raise exc from RemoteTraceback(text)
        return reply[1:]

    def _shared(self, numel, dtype):
        """A tensor (numel,) of `dtype` in a file both processes map; its path joins `_mapped`."""
        folder = "/dev/shm" if os.access("/dev/shm", os.W_OK) else None
        handle, path = tempfile.mkstemp(prefix="velogauss-aux-", dir=folder)
        os.close(handle)
        self._mapped.append((path, numel, dtype))
        return _mapped(path, numel, dtype)

    def _unlink(self):
        for path, _, _ in self._mapped:
            Path(path).unlink(missing_ok=True)
        self._mapped.clear()

    def _ended(self):
        self._unlink()
        try:
            code = self._process.wait(timeout=1.0)
        except subprocess.TimeoutExpired:
            code = None
        return RuntimeError(f"auxiliary losses: their process ({self._process.pid}) ended, exit code {code}; "
                            "the training step cannot finish")


class _Pending:
    """`AuxWorker.submit`'s result, once the process has it."""

    def __init__(self, owner, params, flags):
        self._owner, self._params, self._flags = owner, params, flags

    def result(self):
        loss, present = self._owner.receive()
        return loss, self._owner.gradients(self._params, self._flags, present)


class RemoteTraceback(Exception):
    """The traceback of an exception raised in the auxiliary losses' worker (its `__cause__`)."""

    def __str__(self):
        return "\n" + self.args[0]


def serve(conn):
    """The process's loop: a step per message from `conn` until the parent closes it."""
    held = {}
    while True:
        try:
            message = pickle.loads(conn.recv_bytes())
        except (EOFError, OSError):
            return
        try:
            reply = ("done",) + _step(held, *message)
        except Exception as exc:
            reply = ("error", _sendable(exc), traceback.format_exc())
        conn.send_bytes(pickle.dumps(reply, pickle.HIGHEST_PROTOCOL))


def _step(held, extras, n, flags, spec, draws):
    """One step's auxiliary losses in the process: (loss (float), which parameters got a gradient)."""
    if "setup" in extras:
        motion_spec, cfg, threads, files, centres = extras["setup"]
        torch.set_num_threads(threads)
        params, grads = (_mapped(*f) for f in files)
        # Its initial values are never used: every step copies the parent's in.
        motion = MotionParameters(motion_spec, np.random.default_rng(0)).to(params.dtype)
        motion.centre.copy_(torch.tensor(centres, dtype=params.dtype))
        held.update(motion=motion, cfg=cfg, params=params, grads=grads)
    if "canon" in extras:
        held["canon"] = tuple(_mapped(*f) for f in extras["canon"])
    if spec is not None:
        held["spec"] = spec
    motion, (buffer, moving) = held["motion"], held["canon"]
    params = list(motion.parameters())
    with torch.no_grad():
        for p, value, flag in zip(params, _per_parameter(held["params"], params), flags):
            p.copy_(value)
            p.requires_grad_(flag)
    means, quats, scales = (v.view(n, -1).clone() for v in buffer[:sum(_ROWS) * n].split([r * n for r in _ROWS]))
    canon = aux_losses.Canonical(means, quats, scales, moving[:n].clone())
    loss, grads = aux_losses.loss_and_gradients(canon, aux_losses.motion_leaves(motion), held["cfg"], motion.params(),
                                                held["spec"], _tensors(draws))
    found = dict(grads)
    present = []
    for p, out in zip(params, _per_parameter(held["grads"], params)):
        grad = found.get(p)
        if grad is not None:
            out.copy_(grad)
        present.append(grad is not None)
    return float(loss), tuple(present)


def _per_parameter(flat, params):
    """Views of the flat buffer `flat` shaped as each of `params`, in order."""
    return [v.view_as(p) for v, p in zip(flat[:sum(p.numel() for p in params)].split([p.numel() for p in params]),
                                          params)]


def _mapped(path, numel, dtype):
    """The tensor (numel,) of `dtype` in the shared file `path`, mapped."""
    return torch.from_file(path, shared=True, size=numel, dtype=dtype)


def _arrays(draws):
    """`draws` (velogauss.train.aux_losses.Draws) with NumPy arrays for its tensors."""
    return _map_tensors(draws, lambda v: v.numpy())


def _tensors(draws):
    """`_arrays` undone, into tensors of torch's own allocation (aligned as the parent's)."""
    return _map_tensors(draws, lambda v: torch.from_numpy(v).clone())


def _map_tensors(draws, f):
    def one(v):
        if v is None or isinstance(v, (int, float)):
            return v
        if isinstance(v, tuple):
            return type(v)(*(one(u) for u in v))
        return f(v)
    return one(draws)


def _sendable(exc):
    """`exc`, or a RuntimeError with its message where `exc` does not pickle."""
    try:
        pickle.dumps(exc)
        return exc
    except Exception:
        return RuntimeError(f"{type(exc).__name__}: {exc}")


if __name__ == "__main__":
    serve(Connection(int(sys.argv[1])))
