"""The auxiliary losses' worker process (velogauss.train.aux_worker): the same numbers as
`loss_and_gradients` inline, errors that reach the training step, and a process that ends
cleanly."""

import os
import signal
import tempfile
import time

import pytest
import torch

from velogauss.config import load_config
from velogauss.train import aux_losses, aux_worker, loop
from tests.app.test_train import TINY, tiny_scene  # noqa: F401  (the fixture)


@pytest.fixture(scope="module")
def trainer(tiny_scene, tmp_path_factory):  # noqa: F811
    trainer, _ = loop.prepare(load_config(None, [*TINY, "train.threads=1"]), tiny_scene,
                              tmp_path_factory.mktemp("run"))
    # A motion that moves (a new model's is still: zero last layers), so that the collocation
    # points depend on every input the process is sent.
    generator = torch.Generator().manual_seed(0)
    with torch.no_grad():
        for p in trainer.model.motion.parameters():
            p.add_(0.1 * torch.randn(p.shape, generator=generator))
    return trainer


def _inputs(trainer, it):
    """(motion, Canonical, spec, draws) of iteration `it`, the motion networks training."""
    spec = trainer.spec_at(it)
    trainer.freeze_motion(it)
    draws = aux_losses.draw(trainer.cfg, trainer.model, spec, it, trainer.rng, trainer.data.bounds,
                            trainer.sampler.window(it), trainer.device)
    return trainer.model.motion, aux_losses.canonical(trainer.model), spec, draws


def _inline(trainer, motion, canon, spec, draws):
    return aux_losses.loss_and_gradients(canon, aux_losses.motion_leaves(motion), trainer.cfg, motion.params(), spec,
                                         draws)


def _assert_same(a, b):
    (loss_a, grads_a), (loss_b, grads_b) = a, b
    assert float(loss_a) == float(loss_b)
    assert [leaf for leaf, _ in grads_a] == [leaf for leaf, _ in grads_b]
    for (_, ga), (_, gb) in zip(grads_a, grads_b):
        assert (ga is None) == (gb is None)
        assert ga is None or torch.equal(ga, gb)


def test_the_process_computes_the_auxiliary_losses_to_the_last_bit(trainer):
    worker = aux_worker.process()
    it = trainer.adf_start
    motion, canon, spec, draws = _inputs(trainer, it)
    assert draws.physics is not None and draws.mixing is not None
    _assert_same(worker.submit(motion, canon, trainer.cfg, spec, draws).result(),
                 _inline(trainer, motion, canon, spec, draws))
    # Another spec (without the ADF), more Gaussians than its buffer holds (densification),
    # and motion parameters changed in place (the optimiser): each crosses again.
    grown = aux_losses.Canonical(*(torch.cat([v, v]) for v in canon))
    with torch.no_grad():
        motion.code[0].mul_(1.5)
    for spec_now, canon_now in ((spec.without_adf(), canon), (spec, grown)):
        _assert_same(worker.submit(motion, canon_now, trainer.cfg, spec_now, draws).result(),
                     _inline(trainer, motion, canon_now, spec_now, draws))


def test_frozen_parameters_get_no_gradient_from_the_process(trainer):
    motion, canon, spec, draws = _inputs(trainer, trainer.adf_start)
    motion.adf.requires_grad_(False)  # as before the ADF starts learning
    try:
        result = aux_worker.process().submit(motion, canon, trainer.cfg, spec, draws).result()
        _assert_same(result, _inline(trainer, motion, canon, spec, draws))
    finally:
        motion.adf.requires_grad_(True)
    frozen = {id(p) for p in motion.adf.parameters()}
    assert not frozen & {id(leaf) for leaf, _ in result[1]}


def test_an_error_in_the_process_reaches_the_step_with_its_traceback(trainer):
    worker = aux_worker.process()
    motion, canon, spec, draws = _inputs(trainer, trainer.adf_start)
    bad = draws._replace(mixing=torch.tensor([len(canon.means) + 5]))  # past the last Gaussian
    pending = worker.submit(motion, canon, trainer.cfg, spec, bad)
    with pytest.raises(IndexError) as caught:
        pending.result()
    assert isinstance(caught.value.__cause__, aux_worker.RemoteTraceback)
    assert "loss_and_gradients" in str(caught.value.__cause__)
    # The process serves the next step.
    _assert_same(worker.submit(motion, canon, trainer.cfg, spec, draws).result(),
                 _inline(trainer, motion, canon, spec, draws))


def test_a_process_that_ended_says_so_and_a_new_one_starts(trainer):
    worker = aux_worker.process()
    motion, canon, spec, draws = _inputs(trainer, trainer.adf_start)
    os.kill(worker.pid, signal.SIGKILL)
    while worker.alive():
        time.sleep(0.01)
    with pytest.raises(RuntimeError, match="auxiliary losses: their process .* ended"):
        worker.submit(motion, canon, trainer.cfg, spec, draws).result()
    fresh = aux_worker.process()
    assert fresh is not worker and fresh.alive()
    _assert_same(fresh.submit(motion, canon, trainer.cfg, spec, draws).result(),
                 _inline(trainer, motion, canon, spec, draws))


def test_the_process_leaves_ctrl_c_to_the_training_and_no_files(trainer, monkeypatch):
    worker = aux_worker.process()
    # A session of its own: a terminal's Ctrl-C (SIGINT to the foreground group) is not sent to it.
    assert os.getsid(worker.pid) != os.getsid(0)
    made = []  # the files the worker's shared tensors are mapped from
    make = tempfile.mkstemp

    def recorded(*args, **kwargs):
        handle, path = make(*args, **kwargs)
        made.append(path)
        return handle, path

    monkeypatch.setattr(tempfile, "mkstemp", recorded)
    motion, canon, spec, draws = _inputs(trainer, trainer.adf_start)
    more = aux_losses.Canonical(*(torch.cat([v] * 8) for v in canon))  # more than any buffer yet: a new one
    worker.submit(motion, more, trainer.cfg, spec, draws).result()
    assert made and all(os.path.exists(os.path.dirname(path)) for path in made)
    assert not any(os.path.exists(path) for path in made), "unlinked once the process mapped them"


def test_the_process_imports_the_parents_velogauss_from_any_working_folder(trainer, tmp_path, monkeypatch):
    # A folder holding another `velogauss` (an older checkout, say): the process must not
    # import it before the parent's own.
    (tmp_path / "velogauss").mkdir()
    (tmp_path / "velogauss" / "__init__.py").write_text("raise ImportError('not the parent\\'s velogauss')\n")
    monkeypatch.chdir(tmp_path)
    worker = aux_worker.AuxWorker()
    try:
        motion, canon, spec, draws = _inputs(trainer, trainer.adf_start)
        _assert_same(worker.submit(motion, canon, trainer.cfg, spec, draws).result(),
                     _inline(trainer, motion, canon, spec, draws))
    finally:
        worker.close()
