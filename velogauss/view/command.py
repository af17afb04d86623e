"""The `velogauss view` command (registered in velogauss/cli.py)."""

import importlib.util
import socket
import time
from pathlib import Path
from typing import Optional

import typer

from velogauss.errors import user_errors
from velogauss.run import load_run_model, load_run_scene, recorded_data_dir
from velogauss.threads import apply_threads


def view_command(
    run_dir: Path = typer.Argument(..., help="Run folder written by `velogauss train`."),
    host: str = typer.Option("127.0.0.1", help="Address to bind; 0.0.0.0 serves every network interface."),
    port: int = typer.Option(8080, help="TCP port of the viewer's web page."),
    horizon: Optional[float] = typer.Option(
        None, help="End of the time slider (default: max(1.5 × max_time, 1.0)); beyond max_time is the future."),
    resolution: Optional[int] = typer.Option(
        None, help="Longer side of a still frame in pixels (default: 256 on the CPU, 768 on CUDA)."),
    threads: Optional[int] = typer.Option(None, help="CPU threads for torch and the compositing kernels (default: velogauss.threads' choice, see the README)."),
    data: Optional[Path] = typer.Option(None, "--data", help="Scene folder (default: the one the run was trained on)."),
    device: Optional[str] = typer.Option(None, help="Torch device: cpu, cuda ... (default: cuda when available)."),
):
    """Explore a trained run in the browser: orbit the scene, scrub or play time past the observed window
    into the future, show velocity arrows, trajectories and the ground-truth cameras."""
    with user_errors():
        if importlib.util.find_spec("viser") is None:
            raise ValueError("velogauss view needs viser: pip install 'velogauss[view]'")
        if horizon is not None and not horizon > 0:
            raise ValueError(f"--horizon: expected a positive number, got {horizon!r}")
        if resolution is not None and resolution < 16:
            raise ValueError(f"--resolution: expected at least 16 pixels, got {resolution!r}")
        if threads is not None and threads < 1:
            raise ValueError(f"--threads: expected a positive number, got {threads!r}")
        if not 0 < port < 65536:
            raise ValueError(f"--port: expected 1 to 65535, got {port!r}")
        _check_port_free(host, port)
        apply_threads(threads or 0)
        model, cfg = load_run_model(run_dir, device)
        scene = load_run_scene(cfg, data or recorded_data_dir(run_dir))
    from velogauss.view.server import Viewer

    max_time = float(cfg.data.max_time)
    on_cuda = next(model.parameters()).is_cuda
    viewer = Viewer(model, distinct_cameras(scene), max_time, horizon or max(1.5 * max_time, 1.0),
                    scene.background, host, port, resolution or (768 if on_cuda else 256))
    if viewer.port != port:  # another program took the port between the check and the bind
        viewer.stop()
        with user_errors():
            raise ValueError(f"--port: {port} on {host} is in use; pick another with --port")
    typer.echo(f"velogauss viewer of {run_dir}: http://{host}:{viewer.port}  (Ctrl-C stops it)")
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        viewer.stop()


def distinct_cameras(scene):
    """The scene's distinct cameras, training ones first (multi-view video repeats each pose)."""
    frames = list(scene.train) + list(scene.interpolation) + list(scene.extrapolation)
    return list({(f.camera.viewmat.tobytes(), f.camera.K.tobytes()): f.camera for f in frames}.values())


def _check_port_free(host, port):
    """ValueError naming the port when it cannot be bound (viser would silently take the next one)."""
    try:
        with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_STREAM) as probe:
            # As servers do: a port whose last connection is in TIME_WAIT can be bound again.
            probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            probe.bind((host, port))
    except OSError as err:
        raise ValueError(f"--port: cannot serve on {host}:{port} ({err.strerror}); "
                         "pick another port with --port or another address with --host") from None
