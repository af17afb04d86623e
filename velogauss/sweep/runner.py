"""Run a sweep's points on Ray: one training run per Ray task, resumable, failure-tolerant.

`run_sweep(sweep, out_dir, address=None, cpus=None)`:

1. Generates each catalogue scene once into `OUT/data/<scene>/` (into a temporary folder that
   is renamed when complete, so a killed sweep never leaves a half-written scene behind).
2. Plans every point (`plan_point`): its run folder `OUT/<name>/` is *skipped* when it holds
   `metrics.json` and a `config.toml` equal to the point's config (its "auto" keys as the run
   resolved them, `velogauss.config.resolve_from_run`); *resumed* from its latest
   checkpoint when the config is equal but training or evaluation did not finish; *failed*
   (not touched) when it holds a different config, so nobody's results are overwritten;
   otherwise trained from the start. A config that does not resolve (a bad `set` value)
   fails that point alone.
3. Submits one Ray task per point to train (`train_point`) with `num_cpus=point.threads`;
   the task sets torch's and numba's thread counts to the same number before any heavy work.
   Exceptions inside a task, and a task whose worker died, become the point's recorded
   error; the other points go on.
4. Rewrites the report (`velogauss.sweep.report.write_report`) after every finished point,
   so a killed sweep still leaves the results of what finished.

Ray runs locally by default (`ray.init()` with this machine's CPUs, or `cpus`); `address`
joins an existing cluster (`ray start --head` on one machine, `ray start --address=...` on
the others): then every node needs velogauss installed and the data and `OUT` on a shared
file system.
"""

import dataclasses
import os
import shutil
import tempfile
import time
import traceback
from pathlib import Path

from velogauss.run import build_config, load_run_scene, run_evaluation, with_data_dir
from velogauss.sweep.report import run_metrics, write_report


@dataclasses.dataclass(frozen=True)
class Plan:
    """What to do with one point: `action` is "skip", "resume", "train" or "fail"."""

    point: object
    run_dir: Path
    data_dir: Path
    action: str
    error: str = ""


def point_config(point, config_path, data_dir):
    """The point's training `Config`: `config_path` (or the defaults), its ablation, seed and
    `set` overrides, with `data.dir` = `data_dir`. ValueError naming the key when one is bad."""
    overrides = [f"model.ablation={point.ablation}", f"train.seed={point.seed}", *point.overrides]
    return with_data_dir(build_config(config_path, overrides), data_dir)


def plan_point(point, config_path, out_dir):
    """Decide whether `point` is skipped, resumed, trained or failed (see the module docstring)."""
    from velogauss.config import DataConfig, load_config, resolve_from_run

    run_dir = Path(out_dir) / point.name
    data_dir = Path(point.data) if point.data else Path(out_dir) / "data" / point.scene
    try:
        cfg = point_config(point, config_path, data_dir)
    except ValueError as err:
        return Plan(point, run_dir, data_dir, "fail", f"config: {err}")
    if point.data and not data_dir.is_dir():
        return Plan(point, run_dir, data_dir, "fail", f"scene folder not found: {data_dir}")
    saved = run_dir / "config.toml"
    if not saved.is_file():
        return Plan(point, run_dir, data_dir, "train")
    try:
        previous = load_config(saved)
    except ValueError as err:
        previous = err
    # A run folder records the numbers its "auto" keys resolved to, and a resumed run uses them.
    if not isinstance(previous, ValueError):
        # A future split's window end is derived from the data (spec/data.md), and a generated
        # scene's own window end and background apply where the config left the defaults
        # (velogauss.train.loop.prepare): the run's values stand.
        own = {key: getattr(previous.data, key) for key in ("max_time", "background")
               if getattr(cfg.data, key) == getattr(DataConfig(), key)}
        if cfg.data.split != "time" and previous.data.split == cfg.data.split:
            own["max_time"] = previous.data.max_time
        cfg = dataclasses.replace(cfg, data=dataclasses.replace(cfg.data, **own))
    if isinstance(previous, ValueError) or resolve_from_run(previous, previous) != resolve_from_run(cfg, previous):
        return Plan(point, run_dir, data_dir, "fail",
                    f"{saved}: the run folder holds a different config; move it away or change `out` "
                    "(it was left untouched)")
    if (run_dir / "metrics.json").is_file():
        return Plan(point, run_dir, data_dir, "skip")
    has_checkpoint = (run_dir / "checkpoints" / "latest.pt").is_file()
    return Plan(point, run_dir, data_dir, "resume" if has_checkpoint else "train")


def train_point(plan, config_path, threads):
    """Train, evaluate and score one point (the body of its Ray task); never raises.

    Returns `{"status": "ok", "metrics": {...}, "wall_s": float}` or
    `{"status": "failed", "error": "<exception type>: <message>", "traceback": str}`.
    """
    from velogauss.threads import apply_threads

    # Before any heavy work: this run may use exactly the CPUs Ray reserved for it.
    apply_threads(threads)
    start = time.perf_counter()
    try:
        from velogauss.train.loop import train

        cfg = point_config(plan.point, config_path, plan.data_dir)
        scene = load_run_scene(cfg, plan.data_dir)
        model = train(cfg, scene, plan.run_dir, resume=plan.action == "resume", progress=False)
        run_evaluation(plan.run_dir, model, scene, ("interpolation", "extrapolation"), None)
        return {"status": "ok", "metrics": run_metrics(plan.run_dir), "wall_s": time.perf_counter() - start}
    except Exception as err:  # noqa: BLE001  (any failure of one run is recorded; the sweep goes on)
        return {"status": "failed", "error": f"{type(err).__name__}: {err}", "traceback": traceback.format_exc()}


def make_scenes(sweep, out_dir, echo=print):
    """Generate each catalogue scene of `sweep` that `out_dir/data/` does not hold yet."""
    from velogauss.scenes import make_scene

    for scene in dict.fromkeys(p.scene for p in sweep.points if p.scene):
        final = Path(out_dir) / "data" / scene
        if final.is_dir():
            continue
        final.parent.mkdir(parents=True, exist_ok=True)
        echo(f"generating scene {scene!r} into {final}")
        tmp = Path(tempfile.mkdtemp(dir=final.parent, prefix=f".{scene}."))
        try:
            make_scene(scene, tmp, **sweep.scene_options)
            os.replace(tmp, final)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)


def run_sweep(sweep, out_dir, address=None, cpus=None, echo=print):
    """Run every point of `sweep` into `out_dir` (see the module docstring); return
    `{point name: outcome}` with outcome `{"status": "ok" | "skipped" | "failed", ...}`."""
    import ray

    out_dir = Path(out_dir).resolve()
    make_scenes(sweep, out_dir, echo)
    plans = [plan_point(p, sweep.config, out_dir) for p in sweep.points]
    outcomes = {}
    for plan in plans:
        if plan.action == "skip":
            outcomes[plan.point.name] = {"status": "skipped", "metrics": run_metrics(plan.run_dir)}
            echo(f"skip    {plan.point.name} (metrics.json for the same config)")
        elif plan.action == "fail":
            outcomes[plan.point.name] = {"status": "failed", "error": plan.error}
            echo(f"failed  {plan.point.name}: {plan.error}")
    todo = [p for p in plans if p.action in ("train", "resume")]
    write_report(out_dir, sweep.points, outcomes)
    if not todo:
        return outcomes
    if address is None:
        ray.init(num_cpus=cpus, include_dashboard=False, logging_level="WARNING", log_to_driver=False)
    else:
        try:
            ray.init(address=address, include_dashboard=False, logging_level="WARNING", log_to_driver=False)
        except (ConnectionError, RuntimeError) as err:
            raise ValueError(f"--address: cannot join a Ray cluster at {address!r} ({err})") from None
    try:
        # One process a run (max_calls=1): its peak resident memory, logged by the training, is its own.
        remote = ray.remote(max_calls=1)(train_point)
        pending = {remote.options(num_cpus=p.point.threads, name=p.point.name, max_retries=0)
                   .remote(p, sweep.config, p.point.threads): p for p in todo}
        echo(f"{len(todo)} run(s) on Ray ({ray.cluster_resources().get('CPU', 0):g} CPUs); "
             f"{len(plans) - len(todo)} already settled")
        while pending:
            [ref], _ = ray.wait(list(pending), num_returns=1)
            plan = pending.pop(ref)
            try:
                outcome = ray.get(ref)
            except ray.exceptions.RayError as err:  # the worker died (out of memory, killed, ...)
                outcome = {"status": "failed", "error": f"{type(err).__name__}: {str(err).splitlines()[0]}"}
            outcomes[plan.point.name] = outcome
            done = sum(o["status"] != "skipped" for o in outcomes.values())
            if outcome["status"] == "ok":
                echo(f"ok      {plan.point.name} ({outcome['wall_s'] / 60:.1f} min) [{done}/{len(plans)}]")
            else:
                echo(f"failed  {plan.point.name}: {outcome['error']} [{done}/{len(plans)}]")
            write_report(out_dir, sweep.points, outcomes)
    finally:
        ray.shutdown()
    return outcomes
