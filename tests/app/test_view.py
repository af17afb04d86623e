"""Tests of velogauss/view: the browser camera ↔ Camera conversion, the render callback against
`model.render`, the observed/future banner, bad input, and the viewer end to end in headless
Chromium (skipped, with the reason, where no Chromium is installed)."""

import base64
import copy
import io
import json
import os
import re
import shutil
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image
from typer.testing import CliRunner

pytest.importorskip("viser", reason="viser is not installed (pip install 'velogauss[view]')")

from velogauss.cli import app  # noqa: E402
from velogauss.config import load_config  # noqa: E402
from velogauss.data import load_scene  # noqa: E402
from velogauss.model import build_model, scene_spec  # noqa: E402
from velogauss.scenes import make_scene  # noqa: E402
from velogauss.train import loop  # noqa: E402
from velogauss.view.frame import (BANNER_HEIGHT, FUTURE_COLOR, OBSERVED_COLOR, FrameRenderer, annotate,  # noqa: E402
                                  camera_from_pose, pose_from_camera)

ROOT = Path(__file__).resolve().parents[2]
TINY = ["train.iterations=12", "train.warmup=3", "train.curriculum=4", "train.eval_every=6",
        "train.checkpoint_every=6", "densify.start=2", "densify.every=4", "densify.until=10",
        "physics.n_points=64", "physics.ramp=2", "model.hidden=16", "model.depth=1", "model.n_patterns=4",
        "model.code_dim=4",
        # The toss's declared effects and rigid patterns, what "auto" resolved to when it read
        # scene.json: the viewer is not about the motion form, and an "auto" form would first train
        # the backtest's probe (velogauss.train.backtest).
        "model.effects=declared", "model.patterns=rigid"]


@pytest.fixture(scope="module")
def tiny_scene(tmp_path_factory):
    path = tmp_path_factory.mktemp("scene") / "toss"
    make_scene("toss", path, resolution=24, n_views=4, n_times=6, n_points=300, n_heldout=1)
    return load_scene(path)


@pytest.fixture(scope="module")
def model(tiny_scene):
    """An untrained model whose zero-initialised heads (ADF, time network) are perturbed, so
    that the full model and its physics-only base state differ."""
    cfg = load_config(None, TINY)
    model = build_model(cfg, scene_spec(cfg, tiny_scene.metadata), tiny_scene.points,
                        tiny_scene.point_colors, np.random.default_rng(0))
    gen = torch.Generator().manual_seed(0)
    with torch.no_grad():
        for p in model.motion.parameters():
            if not p.any():
                p.add_(0.05 * torch.randn(p.shape, generator=gen))
    return model.eval()


def test_browser_pose_round_trips_a_scene_camera(tiny_scene):
    camera = tiny_scene.train[0].camera
    wxyz, position, fov_y, aspect = pose_from_camera(camera)
    back = camera_from_pose(wxyz, position, fov_y, aspect, camera.height)
    np.testing.assert_allclose(back.viewmat, camera.viewmat, atol=1e-12)
    np.testing.assert_allclose(back.K, camera.K, atol=1e-12)
    assert (back.width, back.height) == (camera.width, camera.height)
    np.testing.assert_allclose(position, camera.centre, atol=1e-12)


@pytest.mark.parametrize("t", [0.0, 0.4, 0.95, 1.1])
def test_render_callback_equals_model_render(tiny_scene, model, t):
    reference = copy.deepcopy(model)  # an independent copy: the renderer keeps state of its own
    renderer = FrameRenderer(model, tiny_scene.background)
    wxyz, position, fov_y, aspect = pose_from_camera(tiny_scene.train[1].camera)
    camera = camera_from_pose(wxyz, position, fov_y, aspect, 32)
    with torch.no_grad():
        expected = reference.render(camera, t, tiny_scene.background)[0].numpy()
        base = reference.render(camera, t, tiny_scene.background, spec=reference.spec.without_adf())[0].numpy()
    for _ in range(2):  # again, from the kept Gaussians
        np.testing.assert_array_equal(renderer.render(camera, t), expected)
        np.testing.assert_array_equal(renderer.render(camera, t, physics_only=True), base)
        renderer.render(camera, 0.5 * t + 0.1)
    assert np.abs(expected - base).max() > 1e-4  # the switch shows the ADF's part


def test_banner_says_observed_or_future():
    image = np.full((40, 200, 3), 0.5)
    for t, color in ((0.75, OBSERVED_COLOR), (0.76, FUTURE_COLOR)):
        frame = annotate(image, t, 0.75)
        assert tuple(frame[BANNER_HEIGHT - 1, -1]) == color
        assert (frame[BANNER_HEIGHT:] == 128).all()


def _invoke(*args):
    return CliRunner().invoke(app, ["view", *map(str, args)])


def _assert_one_error(result, *names):
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and all(str(n) in errors[0] for n in names), result.output


def test_bad_run_folders_get_one_clear_line(tmp_path):
    _assert_one_error(_invoke(tmp_path / "nowhere", "--port", _free_port()), "run folder not found", "nowhere")
    (tmp_path / "empty").mkdir()
    _assert_one_error(_invoke(tmp_path / "empty", "--port", _free_port()), "checkpoint", "latest.pt")


def test_port_in_use_gets_one_clear_line(tmp_path):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        _assert_one_error(_invoke(tmp_path, "--port", port), "--port", str(port))


def _free_port():
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


class DevTools:
    """A minimal Chrome DevTools Protocol client over the page's websocket."""

    def __init__(self, url):
        from websockets.sync.client import connect

        self.ws = connect(url, max_size=None, open_timeout=30)
        self.next_id = 0

    def call(self, method, **params):
        self.next_id += 1
        self.ws.send(json.dumps({"id": self.next_id, "method": method, "params": params}))
        while True:
            message = json.loads(self.ws.recv(timeout=60))
            if message.get("id") == self.next_id:
                if "error" in message:
                    raise RuntimeError(f"{method}: {message['error']}")
                return message["result"]

    def wait_for(self, event, timeout=60):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if json.loads(self.ws.recv(timeout=timeout)).get("method") == event:
                return
        raise TimeoutError(event)

    def screenshot(self):
        data = self.call("Page.captureScreenshot", format="png")["data"]
        return np.asarray(Image.open(io.BytesIO(base64.b64decode(data))).convert("RGB"))


def _banner_pixels(shot, color):
    return int(np.all(np.abs(shot.astype(int) - color) <= 12, axis=-1).sum())


@pytest.mark.slow
@pytest.mark.skipif(CHROMIUM is None, reason="no Chromium installed (Debian: apt-get install chromium); "
                                             "scripts/setup.sh installs it when CI=true")
def test_viewer_serves_rendered_frames_to_headless_chromium(tiny_scene, tmp_path):
    run = tmp_path / "run"
    loop.train(load_config(None, TINY + [f"data.dir=\"{tiny_scene.root}\""]), tiny_scene, run, progress=False)
    port = _free_port()
    env = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}
    viewer = subprocess.Popen([sys.executable, "-m", "velogauss", "view", str(run), "--port", str(port),
                               "--threads", "1", "--resolution", "128"], cwd=ROOT, env={**os.environ, **env},
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    browser = None
    try:
        line = ""
        deadline = time.monotonic() + 120
        while "http://" not in line and time.monotonic() < deadline and viewer.poll() is None:
            line = viewer.stdout.readline()
        assert f"http://127.0.0.1:{port}" in line, line + (viewer.stdout.read() if viewer.poll() is not None else "")
        browser = subprocess.Popen([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                                    "--remote-debugging-port=0", f"--user-data-dir={tmp_path / 'profile'}",
                                    "--window-size=800,600", "about:blank"],
                                   stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        match = None
        while match is None and time.monotonic() < deadline:
            match = re.search(r"DevTools listening on ws://127.0.0.1:(\d+)/", browser.stderr.readline())
        assert match, "Chromium did not open its DevTools port"
        pages = json.loads(urllib.request.urlopen(f"http://127.0.0.1:{match.group(1)}/json/list").read())
        page = DevTools(next(p for p in pages if p["type"] == "page")["webSocketDebuggerUrl"])
        page.call("Page.enable")
        page.call("Page.navigate", url=f"http://127.0.0.1:{port}")
        page.wait_for("Page.loadEventFired")
        # The frame has arrived when the viewer's banner (green: the slider starts at max_time,
        # the end of the observed window) is on screen; the first frame compiles numba's kernels.
        shot = page.screenshot()
        while _banner_pixels(shot, OBSERVED_COLOR) < 200 and time.monotonic() < deadline:
            time.sleep(0.5)
            shot = page.screenshot()
        Image.fromarray(shot).save(tmp_path / "viewer.png")
        assert _banner_pixels(shot, OBSERVED_COLOR) >= 200, f"no rendered frame on screen: {tmp_path / 'viewer.png'}"
        # Not blank: the rendered scene below the banner is not one flat colour.
        rows = np.nonzero(np.all(np.abs(shot.astype(int) - OBSERVED_COLOR) <= 12, axis=-1).any(axis=1))[0]
        below = shot[rows.max() + 5:, : shot.shape[1] // 2].astype(float) / 255
        assert below.std(axis=(0, 1)).max() > 0.02
    finally:
        viewer.terminate()
        viewer.wait(timeout=30)
        if browser is not None:
            browser.kill()
            browser.wait(timeout=30)


def test_viewer_bench_quick(tmp_path):
    from velogauss.bench import viewer

    threads = torch.get_num_threads()
    try:
        rows = viewer.run(tmp_path / "RESULTS.md", quick=True, threads=1)
    finally:
        torch.set_num_threads(threads)
    text = (tmp_path / "RESULTS.md").read_text()
    assert viewer.SECTION in text and "Load average" in text
    assert [r["kind"] for r in rows] == ["orbit", "orbit, moving (half resolution)", "play"]
    assert all(r["fps"] > 0 and r["min"] <= r["fps"] <= r["max"] and r["cpu_s"] > 0 for r in rows)
    assert sum(line.startswith("| ") for line in text.split(viewer.SECTION)[1].splitlines()) == 1 + len(rows)


def test_controls_drive_the_overlays_and_the_status(tiny_scene, model):
    from velogauss.view.command import distinct_cameras
    from velogauss.view.server import OVERLAY_GAUSSIANS, Viewer

    viewer = Viewer(copy.deepcopy(model), distinct_cameras(tiny_scene), 0.75, 1.125, tiny_scene.background,
                    "127.0.0.1", _free_port(), 32)
    try:
        assert viewer.time.value == 0.75 and "observed window" in viewer.status.content
        viewer.time.value = 0.9
        assert "future" in viewer.status.content
        assert viewer._velocity is None and viewer._trajectories is None
        viewer.show_velocity.value = True
        viewer.show_trajectories.value = True
        n = min(OVERLAY_GAUSSIANS, len(model.gaussians))
        # Arrows start at the tracked positions at t and end ARROW_DT of motion further.
        arrows = viewer._velocity.points
        assert arrows.shape == (n, 2, 3)
        with torch.no_grad():
            start = model.tracked_positions(0.9)[viewer._overlay_gaussians()].numpy()
        np.testing.assert_allclose(arrows[:, 0], start, rtol=1e-5, atol=1e-6)
        # Trajectories: consecutive segments over [0, horizon] (with max_time inserted), red once t > max_time.
        segments = viewer._trajectories.points
        assert segments.shape[1:] == (2, 3) and segments.shape[0] % n == 0
        assert {tuple(c) for c in viewer._trajectories.colors.reshape(-1, 3)} == {OBSERVED_COLOR, FUTURE_COLOR}
        viewer.show_velocity.value = False
        assert viewer._velocity is None
        viewer.mode.value = "physics-only base state (ADF off)"
        assert viewer.physics_only
        assert len(viewer._frusta) == len(distinct_cameras(tiny_scene)) == 4
    finally:
        viewer.stop()


def test_view_help():
    result = CliRunner().invoke(app, ["view", "--help"])
    assert result.exit_code == 0 and "--host" in result.output and "127.0.0.1" in result.output
