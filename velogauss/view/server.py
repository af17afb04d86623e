"""The 4D viewer's server: a viser scene with the model's frames as its background image.

Per browser tab, a render thread waits for a change (camera, time, a control) and sends a
JPEG of `FrameRenderer.render`. While the camera moves it renders at `MOVING_SCALE` of the
resolution (as gsplat's viewer does) and, once the camera has rested `SETTLE_S`, once more
at full resolution. Controls (viser GUI):

- time slider 0 … horizon with marks at 0, max_time ("future →") and the horizon, and
  play/pause; the frame's banner and a line under the slider say observed or future;
- "model": full (physics + ADF) or the physics-only base state (ADF off); in velogauss the
  base state *is* the model with its ADF off (VG-ADF-COMPOSE), so the ADF on/off toggle and
  this switch are one control; it is disabled for a model without an ADF;
- checkboxes: learned velocity arrows (the motion over `ARROW_DT` of normalised time, at
  the `OVERLAY_GAUSSIANS` most opaque Gaussians), their trajectories over [0, horizon]
  (green observed, red future), and the ground-truth camera frusta (off at first: the
  orbit starts inside the first one; click one to look through it).
"""

import threading
import time

import numpy as np
import torch
import viser

from velogauss.view.frame import FUTURE_COLOR, OBSERVED_COLOR, FrameRenderer, annotate, camera_from_pose, pose_from_camera

MOVING_SCALE = 0.5
SETTLE_S = 0.25
JPEG_QUALITY = 85
PLAY_SECONDS = 8.0  # one pass over [0, horizon] while playing
TIME_STEP = 0.005
OVERLAY_GAUSSIANS = 120
TRAJECTORY_TIMES = 41
ARROW_DT = 0.1


class Viewer:
    """A running viewer of `model` (a trained `VeloGaussModel`) on `host:port`.

    `cameras`: the scene's ground-truth `Camera`s (the first one starts the orbit);
    `max_time`: end of the observed window; `horizon` > 0: the slider's end;
    `resolution`: the longer side of a still frame in pixels; `background`: RGB (3,).
    """

    def __init__(self, model, cameras, max_time, horizon, background, host, port, resolution):
        self.model, self.cameras = model, list(cameras)
        self.max_time, self.horizon, self.resolution = float(max_time), float(horizon), int(resolution)
        self.renderer = FrameRenderer(model, background)
        self.server = viser.ViserServer(host=host, port=port, verbose=False)
        self.server.scene.set_up_direction(_up_direction(self.cameras))
        self.server.gui.configure_theme(control_width="medium")
        self._clients = {}
        self._stopped = threading.Event()
        self._build_gui()
        self._frusta = self._add_frusta()
        self._velocity = None
        self._trajectories = None
        self._overlay_index = None
        self.server.on_client_connect(self._connect)
        self.server.on_client_disconnect(self._disconnect)
        threading.Thread(target=self._play_loop, daemon=True).start()

    @property
    def port(self):
        return self.server.get_port()

    def stop(self):
        self._stopped.set()
        for loop in list(self._clients.values()):
            loop.stop()
        self.server.stop()

    # --- controls ---------------------------------------------------------------------

    def _build_gui(self):
        gui = self.server.gui
        self.time = gui.add_slider("time", min=0.0, max=self.horizon, step=TIME_STEP,
                                   initial_value=min(self.max_time, self.horizon),
                                   marks=((0.0, "0"), (self.max_time, f"{self.max_time:g} future →"),
                                          (self.horizon, f"{self.horizon:g}")))
        self.status = gui.add_markdown(self._status_text())
        self.play = gui.add_button("play", icon=viser.Icon.PLAYER_PLAY)
        self.playing = False
        has_adf = self.model.spec.adf
        self.mode = gui.add_dropdown("model", ("full (physics + ADF)", "physics-only base state (ADF off)"),
                                     disabled=not has_adf,
                                     hint="The physics-only base state x*, q*, s* is the model with its ADF off.")
        self.show_velocity = gui.add_checkbox("velocity arrows", False, disabled=not self.model.has_velocity)
        self.show_trajectories = gui.add_checkbox("trajectories", False)
        self.show_frusta = gui.add_checkbox("ground-truth cameras", False)

        self.time.on_update(lambda _: self._time_changed())
        self.mode.on_update(lambda _: self._redraw(overlays=True))
        self.show_velocity.on_update(lambda _: self._redraw(overlays=True))
        self.show_trajectories.on_update(lambda _: self._redraw(overlays=True))
        self.show_frusta.on_update(lambda _: self._set_frusta_visible())

        @self.play.on_click
        def _(_):
            self.playing = not self.playing
            self.play.label = "pause" if self.playing else "play"
            self.play.icon = viser.Icon.PLAYER_PAUSE if self.playing else viser.Icon.PLAYER_PLAY

    @property
    def physics_only(self):
        return self.mode.value.startswith("physics")

    def _status_text(self):
        t = self.time.value if hasattr(self, "time") else self.max_time
        if t > self.max_time:
            return f"**t = {t:.3f}: future** (extrapolated; observed window ends at {self.max_time:g})"
        return f"**t = {t:.3f}: observed window** (0 … {self.max_time:g})"

    def _time_changed(self):
        self.status.content = self._status_text()
        self._redraw(overlays=True)

    def _redraw(self, overlays=False):
        if overlays:
            self._update_overlays()
        for loop in list(self._clients.values()):
            loop.request()

    def _play_loop(self):
        last = time.monotonic()
        while not self._stopped.wait(0.05):
            now = time.monotonic()
            if self.playing:
                t = self.time.value + (now - last) * self.horizon / PLAY_SECONDS
                self.time.value = round((t if t <= self.horizon else 0.0) / TIME_STEP) * TIME_STEP
            last = now

    # --- scene overlays ---------------------------------------------------------------

    def _add_frusta(self):
        handles = []
        extent = _camera_extent(self.cameras)
        for i, camera in enumerate(self.cameras):
            wxyz, position, fov_y, aspect = pose_from_camera(camera)
            handle = self.server.scene.add_camera_frustum(
                f"/cameras/{i}", fov=fov_y, aspect=aspect, scale=0.08 * extent, wxyz=wxyz, position=position,
                color=(60, 60, 60), thickness=1.5, thickness_units="screen", visible=False)

            def look_through(event, camera=camera):
                self._look_through(event.client, camera)

            handle.on_click(look_through)
            handles.append(handle)
        return handles

    def _set_frusta_visible(self):
        for handle in self._frusta:
            handle.visible = self.show_frusta.value

    def _overlay_gaussians(self):
        if self._overlay_index is None:
            opacity = self.model.gaussians.opacities.detach().reshape(-1)
            count = min(OVERLAY_GAUSSIANS, opacity.numel())
            self._overlay_index = torch.sort(torch.topk(opacity, count).indices).values
        return self._overlay_index

    def _positions(self, t):
        with self.renderer.lock, torch.no_grad():
            return self.model.tracked_positions(float(t))[self._overlay_gaussians()]

    def _update_overlays(self):
        """Arrows and trajectories follow the switches; computed only when shown."""
        scene = self.server.scene
        if self.show_velocity.value and self.model.has_velocity:
            t = float(self.time.value)
            x = self._positions(t)
            with self.renderer.lock, torch.no_grad():
                v = self.model.velocity_at(x, t)
            segments = torch.stack([x, x + ARROW_DT * v], dim=1).cpu().numpy().astype(np.float32)
            self._velocity = scene.add_line_segments("/velocity", segments, (255, 140, 0), thickness=2.0,
                                                     thickness_units="screen")
        elif self._velocity is not None:
            self._velocity.remove()
            self._velocity = None
        if self.show_trajectories.value and self._trajectories is None:
            times = np.unique(np.concatenate([np.linspace(0.0, self.horizon, TRAJECTORY_TIMES), [self.max_time]]))
            paths = np.stack([self._positions(t).cpu().numpy() for t in times])  # (T, M, 3)
            segments = np.stack([paths[:-1], paths[1:]], axis=2).reshape(-1, 2, 3).astype(np.float32)
            future = np.repeat(times[1:] > self.max_time, paths.shape[1])
            colors = np.where(future[:, None, None], FUTURE_COLOR, OBSERVED_COLOR).astype(np.uint8)
            self._trajectories = scene.add_line_segments("/trajectories", segments, np.broadcast_to(colors, segments.shape),
                                                         thickness=1.0, thickness_units="screen")
        elif not self.show_trajectories.value and self._trajectories is not None:
            self._trajectories.remove()
            self._trajectories = None

    # --- clients ----------------------------------------------------------------------

    def _connect(self, client):
        loop = _ClientLoop(self, client)
        self._clients[client.client_id] = loop
        if self.cameras:
            self._look_through(client, self.cameras[0])
        client.camera.on_update(lambda _: loop.request(moving=True))
        loop.start()
        loop.request()

    def _disconnect(self, client):
        loop = self._clients.pop(client.client_id, None)
        if loop is not None:
            loop.stop()

    def _look_through(self, client, camera):
        wxyz, position, fov_y, _ = pose_from_camera(camera)
        with client.atomic():
            client.camera.wxyz = wxyz
            client.camera.position = position
            client.camera.fov = fov_y
            client.camera.look_at = position + camera.forward * np.linalg.norm(camera.centre)

    def frame(self, camera_handle, scale):
        """The annotated uint8 frame for one client's camera at `scale` of the resolution."""
        aspect = camera_handle.aspect
        height = self.resolution / max(aspect, 1.0) * scale
        camera = camera_from_pose(camera_handle.wxyz, camera_handle.position, camera_handle.fov, aspect, height)
        t = float(self.time.value)
        return annotate(self.renderer.render(camera, t, self.physics_only), t, self.max_time)


class _ClientLoop(threading.Thread):
    """Renders for one browser tab whenever something changed (see the module docstring)."""

    def __init__(self, viewer, client):
        super().__init__(daemon=True)
        self.viewer, self.client = viewer, client
        self._event = threading.Event()
        self._stop = threading.Event()
        self._moved = 0.0
        self._sharp = True

    def request(self, moving=False):
        if moving:
            self._moved = time.monotonic()
        self._event.set()

    def stop(self):
        self._stop.set()
        self._event.set()

    def run(self):
        while not self._stop.is_set():
            changed = self._event.wait(timeout=SETTLE_S / 2)
            self._event.clear()
            moving = time.monotonic() - self._moved < SETTLE_S
            if not changed and (self._sharp or moving):
                continue
            image = self.viewer.frame(self.client.camera, MOVING_SCALE if moving else 1.0)
            if self._stop.is_set():  # the tab closed while this frame was rendered
                return
            self.client.scene.set_background_image(image, format="jpeg", jpeg_quality=JPEG_QUALITY)
            self._sharp = not moving


def _camera_extent(cameras):
    if not cameras:
        return 1.0
    centres = np.stack([c.centre for c in cameras])
    return float(max(np.linalg.norm(centres - centres.mean(axis=0), axis=1).max(), 1e-3))


def _up_direction(cameras):
    """The scene's up: minus the mean of the cameras' image-down (+y) axes in the world."""
    if not cameras:
        return "+z"
    down = np.mean([c.viewmat[1, :3] for c in cameras], axis=0)
    return -down / np.linalg.norm(down) if np.linalg.norm(down) > 0 else "+z"
