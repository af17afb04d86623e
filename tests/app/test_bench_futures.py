"""`velogauss bench futures` (velogauss.bench.futures): a trained run's extrapolation under every
future, without retraining, and each policy's spread over runs."""

import json

import pytest
from typer.testing import CliRunner

from velogauss.bench import futures
from velogauss.cli import app
from velogauss.scenes import make_scene

TINY = ["model.hidden=8", "model.depth=1", "model.n_patterns=3", "model.code_dim=2", "train.iterations=6",
        "train.warmup=2", "train.curriculum=2", "physics.n_points=16", "train.eval_every=0",
        "model.patterns=mlp", "model.future=fit"]


@pytest.fixture(scope="module")
def fitted_run(tmp_path_factory):
    """A toss run trained briefly under `model.future = "fit"` and evaluated by `velogauss eval`."""
    root = tmp_path_factory.mktemp("futures")
    make_scene("toss", root / "toss", resolution=16, n_views=2, n_times=5, n_points=60, n_heldout=1)
    _train(root / "toss", root / "run", TINY)
    result = CliRunner().invoke(app, ["eval", str(root / "run")])
    assert result.exit_code == 0, result.output
    return root / "run"


def _train(scene, run, overrides, *flags):
    args = ["train", str(scene), "--out", str(run), "--no-eval", *flags]
    result = CliRunner().invoke(app, args + [a for item in overrides for a in ("--set", item)])
    assert result.exit_code == 0, result.output


def test_each_future_scores_as_the_evaluation_of_a_run_with_it(fitted_run):
    record = futures.score_run(fitted_run)
    metrics = json.loads((fitted_run / "metrics.json").read_text())
    forecast = json.loads((fitted_run / "forecast.json").read_text())
    # The run's own future is what `velogauss eval` scored past the window, and the refitted
    # forecast chooses what training's did (same paths, same seed).
    assert record["trained"] == record["fit_choice"] == forecast["future"]
    own = record["futures"][record["trained"]]
    assert own["psnr"] == pytest.approx(metrics["splits"]["extrapolation"]["mean"]["psnr"], abs=1e-9)
    assert record["frozen"] == pytest.approx(metrics["freeze_baseline"]["mean"]["psnr"], abs=1e-9)
    # Holding is the freeze baseline; its velocity past the window is zero, a relative error of 1.
    assert record["futures"]["hold"]["psnr"] == record["frozen"]
    assert record["futures"]["hold"]["vel_future"] == pytest.approx(1.0)
    assert set(record["futures"]) == {"hold", "coast", "integrate", "fit"}


def _record(name, trained, frozen, **psnr):
    return {"run": f"/runs/{name}", "trained": trained, "fit_choice": "hold", "frozen": frozen,
            "futures": {f: {"psnr": psnr.get(f, frozen), "vel_future": None} for f in futures.FUTURES}}


def test_policies_compare_each_run_with_its_own_freeze_baseline():
    records = [_record("a", "integrate", 20.0, coast=21.0, integrate=19.0, fit=20.5),
               _record("b", "fit", 30.0, coast=29.0, integrate=33.0, fit=28.0),
               _record("c", "hold", 10.0, coast=10.5, integrate=9.0, fit=10.0)]
    table = futures.gains(records)
    assert table["as trained"] == pytest.approx([-1.0, -2.0, 0.0])
    assert table["best per run (oracle)"] == pytest.approx([1.0, 3.0, 0.5])
    assert table["hold"] == [0.0, 0.0, 0.0]
    text = futures.markdown(records)
    # as trained: median -1, below the baseline on 2 runs; the oracle never below it.
    assert "| as trained | 3 | -1.00 |" in text and text.split("| as trained |")[1].split("\n")[0].endswith("| 2 |")
    assert "| best per run (oracle) | 3 | +1.00 | +0.60 | +0.50 | 0 |" in text
    assert "| b | fit | hold | 30.00 | +0.00 | -1.00 | +3.00 | -2.00 | integrate |" in text


def test_the_command_writes_the_table_and_the_records(fitted_run, tmp_path):
    out = tmp_path / "futures.md"
    result = CliRunner().invoke(app, ["bench", "futures", str(fitted_run), "--write", str(out)])
    assert result.exit_code == 0, result.output
    assert out.read_text() in result.output
    assert [r["run"] for r in json.loads(out.with_suffix(".json").read_text())["runs"]] == [str(fitted_run)]


def test_a_json_write_path_is_refused_before_any_run_is_scored(tmp_path):
    result = CliRunner().invoke(app, ["bench", "futures", str(tmp_path / "nowhere"), "--write", str(tmp_path / "f.json")])
    assert result.exit_code != 0 and "--write" in result.output and "f.json" in result.output
    assert not (tmp_path / "f.json").exists()


def test_a_missing_run_folder_is_one_line_naming_it(tmp_path):
    result = CliRunner().invoke(app, ["bench", "futures", str(tmp_path / "nowhere")])
    assert result.exit_code != 0
    assert "nowhere" in result.output and "Traceback" not in result.output
