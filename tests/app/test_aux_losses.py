"""The auxiliary losses' collocation points near the Gaussians (velogauss.train.aux_losses)."""

import copy

import torch

from velogauss.model.velogauss_model import moving_state_at
from velogauss.train import aux_losses
from tests.app.test_aux_worker import _inputs, trainer  # noqa: F401  (the fixture)
from tests.app.test_train import tiny_scene  # noqa: F401  (the fixture trainer needs)


def test_the_collocation_points_are_the_drawn_gaussians_as_the_whole_batch_moves_them(trainer):  # noqa: F811
    motion, canon, spec, draws = _inputs(trainer, trainer.adf_start)
    d = draws.physics
    assert d is not None and d.index is not None
    # Drawn with replacement from more Gaussians than points: some repeat, most are left out.
    assert len(torch.unique(d.index)) < len(d.index) and int(canon.moving.sum()) > len(torch.unique(d.index))
    # float64 so that the subset and the whole batch agree beyond float32's rounding.
    params = copy.deepcopy(motion).double().params()
    canon = aux_losses.Canonical(*(v.double() if v.is_floating_point() else v for v in canon))
    d = d._replace(offsets=d.offsets.double())
    with torch.no_grad():
        whole = moving_state_at(params, spec, *canon, d.t)[0]
    expected = whole.index_select(0, d.index) + d.offsets
    got = aux_losses.collocation_near(canon, d, params, spec)
    assert spec.adf and float((whole - canon.means).abs().max()) > 1e-3  # the points move, the ADF on
    torch.testing.assert_close(got, expected, rtol=1e-12, atol=1e-12)
