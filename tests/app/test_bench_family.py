"""`velogauss bench family` (velogauss/bench/family.py): the grid that `scenes` writes is one
`velogauss sweep` reads, with the run names `table` reads back; `table`'s rows, spreads and
targets on a hand-written study folder, against numbers worked out by hand below."""

import json

import pytest
from typer.testing import CliRunner

from velogauss.bench import family
from velogauss.cli import app
from velogauss.scenes.family import TUNING_SEEDS
from velogauss.sweep.grid import load_grid


def bench_family(*args, code=0):
    """`velogauss bench family ARGS...` in this process; asserts its exit code."""
    result = CliRunner().invoke(app, ["bench", "family", *map(str, args)])
    assert result.exit_code == code, result.output
    return result


def write_json(path, obj):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(obj))


def scene_json(seed, kinds, rig, px, frames):
    """The parts of a generated scene.json that the table reads."""
    return {"family": {"seed": seed, "parameters": {"kinds": kinds, "rig": rig}},
            "generator": {"resolution": [px, px], "n_times": frames}}


def metrics_json(extrap, frozen=None, interp=None, vel_obs=None, vel_fut=None, trans=(None, None),
                 only=(None, None)):
    """The parts of a run's metrics.json that the table reads (a deform-only run has no velocity);
    `trans` and `only`: the (observed, future) translation part and translation-only score."""
    def window(i, vel):
        return {"relative_l2": vel, "translation_relative_l2": trans[i], "translation_only_relative_l2": only[i]}
    return {"splits": {"interpolation": {"mean": {"psnr": interp}}, "extrapolation": {"mean": {"psnr": extrap}}},
            "freeze_baseline": {"mean": {"psnr": frozen}},
            "motion": {"velocity": {"observed": window(0, vel_obs), "future": window(1, vel_fut)}}}


@pytest.fixture
def study(tmp_path):
    """Four scenes: 3 with both runs but seed 7 without its deform-only run, seed 9 without any.

    seed | kinds          | vel obs | vel fut | extrap | frozen | gain | deform-only | gain
       1 | spin, orbit    | 0.02    | 0.30    | 22     | 23     | -1   | 20          | 2
       3 | flight, still  | 0.04    | 0.08    | 25     | 18     |  7   | 21          | 4
       7 | flight         | 0.10    | 0.12    | 28     | 20     |  8   | —           | —

    The translation part obs / fut and the translation-only score obs / fut: seed 1 0.01 / 0.20
    and 0.5 / 0.6, seed 3 0.03 / 0.05 and 0.2 / 0.3, seed 7 none (a run from before the split).
    """
    for seed, kinds, rig, px, frames in ((1, ["spin", "orbit"], "hemisphere", 96, 30),
                                         (3, ["flight", "still"], "ring", 64, 20),
                                         (7, ["flight"], "monocular", 128, 40), (9, ["pulse"], "ring", 64, 16)):
        write_json(tmp_path / "data" / f"random-{seed}" / "scene.json", scene_json(seed, kinds, rig, px, frames))
    split = {1: {"trans": (0.01, 0.20), "only": (0.5, 0.6)}, 3: {"trans": (0.03, 0.05), "only": (0.2, 0.3)}, 7: {}}
    for seed, numbers in ((1, (22.0, 23.0, 31.0, 0.02, 0.30)), (3, (25.0, 18.0, 30.0, 0.04, 0.08)),
                          (7, (28.0, 20.0, 33.0, 0.10, 0.12))):
        write_json(tmp_path / f"random-{seed}-full-s0" / "metrics.json", metrics_json(*numbers, **split[seed]))
    for seed, extrap in ((1, 20.0), (3, 21.0)):
        write_json(tmp_path / f"random-{seed}-deform-only-s0" / "metrics.json", metrics_json(extrap))
    write_json(tmp_path / "random-3-full-s0" / "motion_form.json", {"choice": "rigid-gravity", "scores": {}})
    # Seed 7: the backtest chose harmonic, the time network trained the window, a rigid forecast was fitted.
    write_json(tmp_path / "random-7-full-s0" / "motion_form.json",
               {"choice": "harmonic", "patterns": "mlp", "future": "fit", "scores": {}})
    write_json(tmp_path / "random-7-full-s0" / "forecast.json", {"choice": "rigid", "future": "fit", "scores": {}})
    # Seed 1 predates provenance.json; seed 3 trained at one commit; seed 7 was resumed, twice, from
    # a changed checkout of another commit.
    write_json(tmp_path / "random-3-full-s0" / "provenance.json",
               [{"iteration": 0, "version": "0.1.0", "commit": "a" * 40, "dirty": False}])
    write_json(tmp_path / "random-7-full-s0" / "provenance.json",
               [{"iteration": 0, "version": "0.1.0", "commit": "b" * 40, "dirty": False},
                {"iteration": 500, "version": "0.1.0", "commit": "c" * 40, "dirty": True},
                {"iteration": 900, "version": "0.1.0", "commit": "c" * 40, "dirty": True}])
    return tmp_path


def section_rows(text, title):
    """The cells of the rows of the one table under `## title`."""
    body = text.split(f"## {title}\n", 1)[1].split("\n## ", 1)[0]
    return [[c.strip() for c in line.strip("|").split("|")] for line in body.splitlines()
            if line.startswith("|")][2:]


def test_table_rows_spreads_and_targets(study):
    text = bench_family("table", "--out", study, "--write", study / "study.md").output
    assert (study / "study.md").read_text() == text
    rows = section_rows(text, "Scenes")
    assert [r[:5] for r in rows] == [["1", "spin, orbit", "hemisphere", "96", "30"],
                                     ["3", "flight, still", "ring", "64", "20"],
                                     ["7", "flight", "monocular", "128", "40"]]
    assert rows[0][5:] == ["0.020", "0.300", "0.010", "0.200", "0.500", "0.600",
                           "31.00", "22.00", "23.00", "-1.00", "20.00", "+2.00", "—", "—"]
    assert rows[1][5:] == ["0.040", "0.080", "0.030", "0.050", "0.200", "0.300",
                           "30.00", "25.00", "18.00", "+7.00", "21.00", "+4.00", "rigid-gravity",
                           "aaaaaaa"]
    assert rows[2][5:] == ["0.100", "0.120", "—", "—", "—", "—", "33.00", "28.00", "20.00", "+8.00", "—", "—",
                           "mlp, forecast rigid", "bbbbbbb, ccccccc+"]
    # Linear percentiles of n sorted values: position q/100 (n - 1). Of 3 values the 90th lies at 1.8
    # (0.8 of the way from the 2nd to the 3rd), the 10th at 0.2; of 2 values at 0.9 and 0.1.
    spreads = {(r[0], r[1]): r[2:] for r in section_rows(text, "Distribution")}
    assert spreads == {
        ("all", "vel. err obs"): ["3", "0.040", "0.088", "0.100"],  # 0.04 + 0.8 × 0.06
        ("all", "vel. err fut"): ["3", "0.120", "0.264", "0.300"],  # 0.12 + 0.8 × 0.18
        ("all", "vel. err obs, translation part"): ["2", "0.020", "0.028", "0.030"],  # 0.01 + 0.9 × 0.02
        ("all", "vel. err fut, translation part"): ["2", "0.125", "0.185", "0.200"],  # 0.05 + 0.9 × 0.15
        ("all", "translation-only model's vel. err obs"): ["2", "0.350", "0.470", "0.500"],  # 0.2 + 0.9 × 0.3
        ("all", "translation-only model's vel. err fut"): ["2", "0.450", "0.570", "0.600"],  # 0.3 + 0.9 × 0.3
        ("all", "extrap − frozen (dB)"): ["3", "7.000", "0.600", "-1.000"],  # -1 + 0.2 × 8
        ("all", "extrap − deform-only (dB)"): ["2", "3.000", "2.200", "2.000"],  # 2 + 0.1 × 2
        ("flight", "vel. err obs"): ["2", "0.070", "0.094", "0.100"],  # 0.04 + 0.9 × 0.06
        ("flight", "vel. err fut"): ["2", "0.100", "0.116", "0.120"],  # 0.08 + 0.9 × 0.04
        ("flight", "vel. err obs, translation part"): ["1", "0.030", "0.030", "0.030"],
        ("flight", "vel. err fut, translation part"): ["1", "0.050", "0.050", "0.050"],
        ("flight", "translation-only model's vel. err obs"): ["1", "0.200", "0.200", "0.200"],
        ("flight", "translation-only model's vel. err fut"): ["1", "0.300", "0.300", "0.300"],
        ("flight", "extrap − frozen (dB)"): ["2", "7.500", "7.100", "7.000"],  # 7 + 0.1 × 1
        ("flight", "extrap − deform-only (dB)"): ["1", "4.000", "4.000", "4.000"],
        **{(kind, metric): values for kind in ("spin", "orbit") for metric, values in (
            ("vel. err obs", ["1", "0.020", "0.020", "0.020"]), ("vel. err fut", ["1", "0.300", "0.300", "0.300"]),
            ("vel. err obs, translation part", ["1", "0.010", "0.010", "0.010"]),
            ("vel. err fut, translation part", ["1", "0.200", "0.200", "0.200"]),
            ("translation-only model's vel. err obs", ["1", "0.500", "0.500", "0.500"]),
            ("translation-only model's vel. err fut", ["1", "0.600", "0.600", "0.600"]),
            ("extrap − frozen (dB)", ["1", "-1.000", "-1.000", "-1.000"]),
            ("extrap − deform-only (dB)", ["1", "2.000", "2.000", "2.000"]))},
    }
    assert section_rows(text, "Targets") == [
        ["median vel. err obs ≤ 0.05", "0.040", "met"], ["median vel. err fut ≤ 0.1", "0.120", "missed"],
        ["90th pct vel. err fut ≤ 0.25", "0.264", "missed"], ["median extrap − frozen (dB) ≥ 6", "7.000", "met"],
        ["median extrap − deform-only (dB) ≥ 3", "3.000", "met"], ["scenes with extrap < frozen = 0", "1", "missed"]]
    missing = text.split("## Missing runs\n", 1)[1].split()
    assert [m for m in missing if m.startswith(str(study))] == [
        str(study / name) for name in ("random-7-deform-only-s0", "random-9-full-s0", "random-9-deform-only-s0")]
    assert 'method="linear"' in text


@pytest.mark.parametrize("report, forecast, label", [
    ({}, {}, None),
    ({"choice": "mlp", "future": "hold"}, {}, "mlp (held)"),
    ({"choice": "rigid", "future": "integrate"}, {}, "rigid"),
    ({"choice": "harmonic", "patterns": "mlp", "future": "fit"}, {"choice": "mlp", "future": "integrate"},
     "mlp, forecast mlp"),
    ({"choice": "rigid", "patterns": "mlp", "future": "fit"}, {"choice": "harmonic", "future": "hold"},
     "mlp, forecast held"),
    # A future the user set to "fit": the form trained the window, and a forecast not yet fitted shows as such.
    ({"choice": "rigid", "patterns": "rigid", "future": "fit"}, {}, "rigid, forecast —"),
])
def test_form_label(report, forecast, label):
    assert family.form_label(report, forecast) == label


def test_table_without_data_or_runs(tmp_path):
    assert "no scenes folder" in bench_family("table", "--out", tmp_path, code=2).output
    write_json(tmp_path / "data" / "random-4" / "scene.json", scene_json(4, ["bounce"], "ring", 64, 16))
    text = bench_family("table", "--out", tmp_path).output
    assert section_rows(text, "Scenes") == []
    assert ["scenes with extrap < frozen = 0", "—", "no data"] in section_rows(text, "Targets")
    assert str(tmp_path / "random-4-full-s0") in text


def test_scenes_writes_a_sweep_grid(tmp_path, monkeypatch):
    rendered = []

    def fake_render(seed, out_dir):  # rendering a real scene takes seconds
        rendered.append(seed)
        write_json(out_dir / "scene.json", scene_json(seed, ["spin"], "ring", 64, 16))

    monkeypatch.setattr(family, "make_random_scene", fake_render)
    write_json(tmp_path / "data" / "random-2" / "scene.json", scene_json(2, ["spin"], "ring", 64, 16))
    output = bench_family("scenes", "--seeds", "2,5,2", "--out", tmp_path, "--set", "train.iterations=50",
                          "--set", "model.integrator=rk4").output
    assert rendered == [5]  # random-2 already holds its scene
    assert f"velogauss sweep {tmp_path / 'grid.toml'}" in output
    sweep = load_grid(tmp_path / "grid.toml")
    assert sweep.out == tmp_path.resolve() and sweep.threads == 1
    points = {(p.data, p.ablation, p.seed): p for p in sweep.points}
    assert set(points) == {(str(tmp_path / "data" / f"random-{s}"), a, 0) for s in (2, 5) for a in family.ABLATIONS}
    for (data, ablation, _), point in points.items():
        assert sweep.out / point.name == family.run_folder(tmp_path, f"random-{data[-1]}", ablation)
        assert point.overrides == ("train.iterations=50", 'model.integrator="rk4"')


@pytest.mark.parametrize("args", [("--seeds", "1,x"), ("--seeds", "-1"), ("--seeds", "0", "--set", "model.nope=1"),
                                  ("--seeds", "0", "--ablations", "full,nope")])
def test_scenes_bad_input_renders_nothing(tmp_path, monkeypatch, args):
    monkeypatch.setattr(family, "make_random_scene", lambda *a: pytest.fail("rendered despite bad input"))
    bench_family("scenes", "--out", tmp_path, *args, code=2)
    assert not (tmp_path / "grid.toml").exists()


def test_parse_seeds():
    assert family.parse_seeds("tuning") == TUNING_SEEDS
    assert family.parse_seeds(" 5, 0,5") == (5, 0)


def test_translation_only_of_drawn_scenes():
    # Seed 1000 of the family is one body spinning in place (kinds ["spin"]): without spin
    # nothing of its motion is left, up to the sample's mean offset from the centre.
    text = bench_family("translation-only", "--seeds", "1000").output
    rows = [[c.strip() for c in line.strip("|").split("|")] for line in text.splitlines()
            if line.startswith("|") and not line.startswith("|--")]
    rows = [r for r in rows if r[0] not in ("seed", "window")]
    assert rows[0][:2] == ["1000", "spin"] and float(rows[0][2]) > 0.99 and float(rows[0][3]) > 0.99
    assert ["observed", "1", rows[0][2], rows[0][2], rows[0][2], "0 (≤ 0.05)"] in rows
