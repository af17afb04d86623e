"""The `velogauss sweep` command (registered in velogauss/cli.py)."""

import importlib.util
from pathlib import Path
from typing import Optional

import typer

from velogauss.errors import user_errors


def sweep_command(
    grid: Path = typer.Argument(..., help="Grid file (TOML); see velogauss/sweep/grid.py and benchmarks/grids/."),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="Sweep folder (default: the grid file's `out`)."),
    address: Optional[str] = typer.Option(
        None, help="Join a running Ray cluster (HOST:PORT, or `auto`) instead of starting Ray on this machine."),
    cpus: Optional[int] = typer.Option(None, help="CPUs local Ray may use (default: all of this machine's)."),
):
    """Train every point of a grid (scenes × ablations × seeds × --set values), one Ray task each; skip
    points already done, record failures and go on; write results.csv, results.md and plots/."""
    from velogauss.sweep.grid import load_grid

    with user_errors():
        sweep = load_grid(grid)
        out = out or sweep.out
        if out is None:
            raise ValueError(f"{grid}: out: no sweep folder; set `out` in the grid file or pass --out")
        if cpus is not None and (cpus < 1 or address is not None):
            raise ValueError(f"--cpus: expected a positive number and no --address, got {cpus!r}")
        if importlib.util.find_spec("ray") is None:
            raise ValueError("velogauss sweep needs Ray: pip install 'velogauss[sweep]'")
    from velogauss.sweep.runner import run_sweep

    with user_errors():  # a bad scene_options value, an unreachable --address
        outcomes = run_sweep(sweep, out, address=address, cpus=cpus, echo=typer.echo)
    failed = sorted(name for name, o in outcomes.items() if o["status"] == "failed")
    typer.echo(f"results: {Path(out) / 'results.md'}, {Path(out) / 'results.csv'}, {Path(out) / 'plots'}/")
    if failed:
        typer.secho(f"{len(failed)} run(s) failed: {', '.join(failed)}", err=True, fg=typer.colors.RED)
        raise typer.Exit(1)
