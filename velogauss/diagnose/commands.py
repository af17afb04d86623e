"""`velogauss diagnose NAME`: the diagnostics' commands (registered in velogauss/cli.py).

Each command imports its diagnostic when it runs, so the other commands start without torch.
"""

from pathlib import Path
from typing import List, Optional

import typer

from velogauss.errors import user_errors

diagnose_app = typer.Typer(
    help="Diagnose where a trained run's motion error comes from, against a generated scene's ground truth.",
    no_args_is_help=True,
)

_RUNS_HELP = "Trained run folders."
_DATA_HELP = "The generated scene (default: RUN_DIR/data), e.g. a fidelity run's CACHE/data/SCENE."


@diagnose_app.command("centre")
def centre_command(
    runs: List[Path] = typer.Argument(..., help=_RUNS_HELP),
    data: Optional[Path] = typer.Option(None, "--data", help=_DATA_HELP),
    times: str = typer.Option("0,0.375,0.75,1", help="Comma-separated times of the velocity errors."),
):
    """Each moving body's centre: the learned velocity, spin and mean accelerations against the truth
    (and, with rigid patterns, how far the pattern's centre is off the true one)."""
    from velogauss.diagnose.centre import report

    with user_errors():
        at = _times(times)
        for run in runs:
            for line in report(run, data, at):
                typer.echo(line)


@diagnose_app.command("visibility")
def visibility_command(
    runs: List[Path] = typer.Argument(..., help=_RUNS_HELP),
    data: Optional[Path] = typer.Option(None, "--data", help=_DATA_HELP),
):
    """The velocity error where the training cameras see the surface and where none does, per body."""
    from velogauss.diagnose.visibility import TABLE_HEADER, table_rows

    with user_errors():
        typer.echo(TABLE_HEADER)
        for run in runs:
            for row in table_rows(run, data):
                typer.echo(row)


@diagnose_app.command("slip")
def slip_command(
    runs: List[Path] = typer.Argument(..., help=_RUNS_HELP),
    data: Optional[Path] = typer.Option(None, "--data", help=_DATA_HELP),
    times: str = typer.Option("0.25,0.5,0.75,1", help="Comma-separated times."),
):
    """Each moving body's Gaussians: their best rigid turn against the body's, how far they slip off
    their material, and how much of that is not rigid."""
    from velogauss.diagnose.slip import TABLE_HEADER, table_rows

    with user_errors():
        at = _times(times)
        typer.echo(TABLE_HEADER)
        for run in runs:
            for row in table_rows(run, data, at):
                typer.echo(row)


def _times(text):
    """The `--times` option's numbers; ValueError naming it when one is not a number."""
    try:
        return [float(t) for t in text.split(",")]
    except ValueError:
        raise ValueError(f"--times: expected comma-separated numbers, got {text!r}") from None
