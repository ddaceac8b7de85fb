"""The simulator's side of the protocol extension: four synthetic cameras, status, battery.

An extended simulator (`ocu-sim --extended`, `RobotSimulator(extended=True)`) answers a hello
from the OCU with status packets and streams every requested camera as fragmented JPEGs;
while hellos keep coming (within the robot watchdog time) it sends no vendor video to that
client. Without hellos it behaves exactly like the vendor robot.

The synthetic cameras show what the documents complain about (seed 001 section IV.D): the
scene is seen through the lens model of the camera's profile calibration (fisheye or
standard distortion) with a green cast that is exactly what the profile's fixed gains undo.
In a world (`ocu-sim --world`) the scene is the world from the camera's mount as the robot
moves (ocu.sim.scene); without one, a colour test pattern with straight grid lines and a
ball circling. Camera name, frame counter
and capture time are burned in, like a camera's on-screen display, and repeated in a
JPEG comment (``ocu-sim camera=<name> index=<k> frame=<n> t_mono=<s> quality=<q>
size=<w>x<h> torch=<0|1>``) for tests and tools.

Battery, headlight and attitude are simulator models, not robot facts: a pack between
BATTERY_EMPTY_V and BATTERY_FULL_V that drains with time (faster while moving); the headlight
is the torch state of the latest RCP; roll and pitch follow a gentle synthetic terrain under
the simulated pose.
"""

from __future__ import annotations

import math
import random
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, cast

import cv2
import numpy as np
import numpy.typing as npt

from ocu.nav.geometry import Pose
from ocu.profile import CameraCalibration, CameraSettings, RobotProfile
from ocu.protocol.extended import ExtendedCodec, HelloPacket, StatusPacket, fragment_frame
from ocu.records import CameraRequest
from ocu.sim.rangefinder import RangeSensor
from ocu.sim.scene import WorldView
from ocu.sim.video import MAX_FRAME_SIDE_PX, MIN_FRAME_SIDE_PX

Pixels = npt.NDArray[np.uint8]
Maps = tuple[npt.NDArray[Any], npt.NDArray[Any]]

MAX_FPS = 60
DEFAULT_STATUS_HZ = 5.0
BATTERY_FULL_V = 25.2
BATTERY_EMPTY_V = 21.0
DEFAULT_DRAIN_PERCENT_PER_S = 0.02
MOTION_DRAIN_FACTOR = 3.0
DARK_GAIN = 0.6
# The simulated IMU's heading noise (1 sigma).
IMU_NOISE_RAD = 0.002
TERRAIN_PITCH_RAD = 0.12
TERRAIN_ROLL_RAD = 0.08
TERRAIN_WAVELENGTH_M = 2.0
# The ideal scene is rendered with this fraction of the calibrated focal length, so the
# distorted (wide) view still finds scene pixels out to its corners.
SCENE_FOCAL_SCALE = 0.6
GRID_CELLS = 8
VIEW_CACHE_SIZE = 16
BALL_RADIUS_FRACTION = 0.08
BALL_STEP_RAD = 0.12
BALL_OUTLINE_RAD = tuple(2 * math.pi * k / 32 for k in range(32))
PALETTE_BGR = (
    (60, 60, 220),
    (60, 200, 60),
    (220, 90, 40),
    (40, 200, 230),
    (200, 60, 200),
    (210, 200, 40),
    (200, 200, 200),
    (90, 90, 90),
)
OSD_COLOUR_BGR = (255, 255, 255)
OSD_FONT = cv2.FONT_HERSHEY_SIMPLEX
CAMERA_BAR_BGR = ((0, 140, 255), (255, 140, 0), (0, 200, 0), (200, 0, 200))
JPEG_COM = b"\xff\xfe"


def jpeg_with_comment(jpeg: bytes, comment: bytes) -> bytes:
    """The JPEG with a COM segment inserted right after its SOI marker."""
    segment = JPEG_COM + (len(comment) + 2).to_bytes(2, "big") + comment
    return jpeg[:2] + segment + jpeg[2:]


def jpeg_comment(jpeg: bytes) -> bytes | None:
    """The first COM segment's text of a JPEG, or None."""
    at = jpeg.find(JPEG_COM)
    if at < 0 or at + 4 > len(jpeg):
        return None
    length = int.from_bytes(jpeg[at + 2 : at + 4], "big")
    return jpeg[at + 4 : at + 2 + length]


def distortion_maps(camera: CameraSettings, size_px: tuple[int, int]) -> Maps | None:
    """Maps that turn an ideal pinhole scene into what the camera's lens sees, or None."""
    calibration = camera.calibration
    if calibration is None:
        return None
    width, height = size_px
    sx = width / calibration.size_px[0]
    sy = height / calibration.size_px[1]
    fx, fy = calibration.focal_px[0] * sx, calibration.focal_px[1] * sy
    cx, cy = calibration.centre_px[0] * sx, calibration.centre_px[1] * sy
    matrix = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    coefficients = np.array(calibration.distortion, dtype=np.float64)
    u, v = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    points = np.stack([u.ravel(), v.ravel()], axis=-1).reshape(-1, 1, 2)
    if calibration.model == "fisheye":
        ideal = cv2.fisheye.undistortPoints(points, matrix, coefficients)
    else:
        ideal = cv2.undistortPoints(points, matrix, coefficients)
    ideal = ideal.reshape(height, width, 2)
    map_x = (ideal[..., 0] * fx * SCENE_FOCAL_SCALE + cx).astype(np.float32)
    map_y = (ideal[..., 1] * fy * SCENE_FOCAL_SCALE + cy).astype(np.float32)
    map1, map2 = cv2.convertMaps(map_x, map_y, cv2.CV_16SC2)
    return np.asarray(map1), np.asarray(map2)


def cast_table(camera: CameraSettings, torch: bool) -> Pixels:
    """The sensor's colour cast (the inverse of the profile's fixed gains, for a calibrated
    camera) and the scene's brightness (dark without the headlight) as a cv2.LUT table.
    """
    gains = camera.fixed_gains_rgb if camera.calibration is not None else (1.0, 1.0, 1.0)
    light = 1.0 if torch else DARK_GAIN
    red, green, blue = (light / max(g, 1e-6) for g in gains)
    levels = np.arange(256, dtype=np.float32)
    columns = [np.clip(levels * gain + 0.5, 0, 255) for gain in (blue, green, red)]
    return np.stack(columns, axis=-1).astype(np.uint8).reshape(1, 256, 3)


def distort_pixel(
    calibration: CameraCalibration, size_px: tuple[int, int], x: float, y: float
) -> tuple[float, float]:
    """Where the lens puts a pixel of the ideal scene (the inverse of distortion_maps)."""
    sx = size_px[0] / calibration.size_px[0]
    sy = size_px[1] / calibration.size_px[1]
    fx, fy = calibration.focal_px[0] * sx, calibration.focal_px[1] * sy
    cx, cy = calibration.centre_px[0] * sx, calibration.centre_px[1] * sy
    xn = (x - cx) / (fx * SCENE_FOCAL_SCALE)
    yn = (y - cy) / (fy * SCENE_FOCAL_SCALE)
    k = calibration.distortion
    if calibration.model == "fisheye":
        r = math.hypot(xn, yn)
        theta = math.atan(r)
        theta_d = theta * (
            1 + k[0] * theta**2 + k[1] * theta**4 + k[2] * theta**6 + k[3] * theta**8
        )
        scale = theta_d / r if r > 1e-12 else 1.0
        xd, yd = xn * scale, yn * scale
    else:
        k3 = k[4] if len(k) > 4 else 0.0
        r2 = xn * xn + yn * yn
        radial = 1 + k[0] * r2 + k[1] * r2 * r2 + k3 * r2**3
        xd = xn * radial + 2 * k[2] * xn * yn + k[3] * (r2 + 2 * xn * xn)
        yd = yn * radial + k[2] * (r2 + 2 * yn * yn) + 2 * k[3] * xn * yn
    return fx * xd + cx, fy * yd + cy


class SyntheticCameras:
    """Draws and encodes the frames of every camera.

    The static scene goes through the lens and the cast once per camera, size and torch
    state; per frame only the moving ball (drawn where the lens puts it) and the on-screen
    text are added before the JPEG encoding, so four 30 fps cameras stay cheap.
    """

    def __init__(self, cameras: tuple[CameraSettings, ...], world: WorldView | None = None) -> None:
        self.cameras = cameras
        self.world = world
        self._maps: dict[tuple[int, tuple[int, int]], Maps | None] = {}
        # The last world view per camera and size, reused while the robot stands still.
        self._world_views: dict[tuple[int, tuple[int, int], bool], tuple[object, Pixels]] = {}
        self._views: dict[tuple[int, tuple[int, int], bool], Pixels] = {}
        self._casts = [(cast_table(c, torch=False), cast_table(c, torch=True)) for c in cameras]

    def _scene(self, camera: int, size_px: tuple[int, int]) -> Pixels:
        width, height = size_px
        scene = np.zeros((height, width, 3), np.uint8)
        cell_w, cell_h = width / GRID_CELLS, height / GRID_CELLS
        for row in range(GRID_CELLS):
            for column in range(GRID_CELLS):
                colour = PALETTE_BGR[(row * 3 + column + camera) % len(PALETTE_BGR)]
                top_left = (round(column * cell_w), round(row * cell_h))
                bottom_right = (round((column + 1) * cell_w), round((row + 1) * cell_h))
                cv2.rectangle(scene, top_left, bottom_right, colour, thickness=-1)
        line = max(1, width // 320)
        for k in range(GRID_CELLS + 1):
            x, y = round(k * cell_w), round(k * cell_h)
            cv2.line(scene, (x, 0), (x, height), (20, 20, 20), line)
            cv2.line(scene, (0, y), (width, y), (20, 20, 20), line)
        return scene

    def view(self, camera: int, size_px: tuple[int, int], torch: bool) -> Pixels:
        """The static scene as the camera sees it: through its lens, with its cast."""
        key = (camera, size_px, torch)
        view = self._views.get(key)
        if view is None:
            view = self._scene(camera, size_px)
            maps = distortion_maps(self.cameras[camera], size_px)
            if maps is not None:
                view = cast(
                    Pixels,
                    cv2.remap(view, *maps, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT),
                )
            cv2.LUT(view, self._casts[camera][int(torch)], dst=view)
            if len(self._views) >= VIEW_CACHE_SIZE:
                self._views.pop(next(iter(self._views)))
            self._views[key] = view
        return view

    def world_view(
        self,
        camera: int,
        size_px: tuple[int, int],
        torch: bool,
        pose: Pose,
        joints_rad: Mapping[str, float] | None = None,
    ) -> Pixels:
        """The world from the camera's mount on the robot at `pose` (and the joints' angles,
        for a camera on the arm): lens and cast applied."""
        assert self.world is not None
        key = (camera, size_px, torch)
        settings = self.cameras[camera]
        link = self.world.link_transform(settings.mount, joints_rad)
        # A camera on a link sees a new picture when the joints move, not only the chassis.
        where = (pose, None if link is None else tuple(np.round(link, 6).ravel()))
        cached = self._world_views.get(key)
        if cached is not None and cached[0] == where:
            return cached[1]
        width, height = size_px
        calibration = settings.calibration
        if calibration is not None:
            sx, sy = width / calibration.size_px[0], height / calibration.size_px[1]
            focal = (
                calibration.focal_px[0] * sx * SCENE_FOCAL_SCALE,
                calibration.focal_px[1] * sy * SCENE_FOCAL_SCALE,
            )
            centre = (calibration.centre_px[0] * sx, calibration.centre_px[1] * sy)
        else:
            focal, centre = (width / 2.0, width / 2.0), (width / 2.0, height / 2.0)
        view = self.world.render(
            pose, settings.mount, size_px, focal, centre, joints_rad=joints_rad
        )
        if (camera, size_px) not in self._maps:
            self._maps[(camera, size_px)] = distortion_maps(settings, size_px)
        maps = self._maps[(camera, size_px)]
        if maps is not None:
            view = cast(
                Pixels, cv2.remap(view, *maps, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
            )
        cv2.LUT(view, self._casts[camera][int(torch)], dst=view)
        if len(self._world_views) >= VIEW_CACHE_SIZE:
            self._world_views.pop(next(iter(self._world_views)))
        self._world_views[key] = (where, view)
        return view

    def _colour(self, camera: int, torch: bool, bgr: tuple[int, int, int]) -> tuple[int, ...]:
        pixel = np.array([[bgr]], dtype=np.uint8)
        return tuple(int(v) for v in cv2.LUT(pixel, self._casts[camera][int(torch)])[0, 0])

    def _lens(
        self, camera: int, size_px: tuple[int, int], x: float, y: float
    ) -> tuple[float, float]:
        calibration = self.cameras[camera].calibration
        if calibration is None:
            return x, y
        return distort_pixel(calibration, size_px, x, y)

    def render(
        self,
        camera: int,
        size_px: tuple[int, int],
        frame_number: int,
        capture_s: float,
        quality: int,
        *,
        torch: bool = False,
        pose: Pose | None = None,
        joints_rad: Mapping[str, float] | None = None,
    ) -> bytes:
        """One JPEG of a camera: the lens view (the world at `pose`, or the test pattern and
        its ball), on-screen text, comment."""
        width, height = size_px
        if self.world is not None and pose is not None:
            image = self.world_view(camera, size_px, torch, pose, joints_rad).copy()
        else:
            image = self.view(camera, size_px, torch).copy()
            self._ball(camera, image, size_px, frame_number, torch)
        name = self.cameras[camera].name
        lines = (
            f"{name} (camera {camera + 1})",
            f"frame {frame_number}",
            f"capture t={capture_s:.3f} s",
            "torch ON" if torch else "torch off",
        )
        self._osd(camera, image, lines, torch, corner=self.world is not None and pose is not None)
        ok, encoded = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, quality])
        if not ok:
            raise RuntimeError("JPEG encoding failed")
        comment = (
            f"ocu-sim camera={name} index={camera} frame={frame_number} "
            f"t_mono={capture_s:.6f} quality={quality} size={width}x{height} torch={int(torch)}"
        ).encode("ascii")
        return jpeg_with_comment(encoded.tobytes(), comment)

    def _ball(
        self, camera: int, image: Pixels, size_px: tuple[int, int], frame_number: int, torch: bool
    ) -> None:
        """The test pattern's ball, circling, drawn through the lens."""
        width, height = size_px
        angle = frame_number * BALL_STEP_RAD
        ball_x = width / 2 + math.cos(angle) * width / 4
        ball_y = height / 2 + math.sin(angle) * height / 4
        radius = max(2.0, min(width, height) * BALL_RADIUS_FRACTION)
        # The ball's outline goes through the lens point by point, so it bends like the grid.
        outline = np.array(
            [
                self._lens(
                    camera,
                    size_px,
                    ball_x + radius * math.cos(step),
                    ball_y + radius * math.sin(step),
                )
                for step in BALL_OUTLINE_RAD
            ],
            dtype=np.float64,
        )
        polygon = np.round(outline * 16).astype(np.int32)  # 4 fractional bits
        white = self._colour(camera, torch, (255, 255, 255))
        cv2.fillPoly(image, [polygon], white, lineType=cv2.LINE_AA, shift=4)
        cv2.polylines(image, [polygon], True, (0, 0, 0), 2, lineType=cv2.LINE_AA, shift=4)

    def _osd(
        self,
        camera: int,
        image: Pixels,
        lines: tuple[str, ...],
        torch: bool,
        *,
        corner: bool = False,
    ) -> None:
        height, width = image.shape[:2]
        scale = max(0.35, height / 480 * (0.5 if corner else 0.7))
        thickness = max(1, round(scale * 2))
        line_px = round(28 * scale) + 4
        # Over the world the text keeps to the top-left corner, out of the way.
        left, top = (12, line_px + 4) if corner else (width // 4, height // 4)
        text_w = max(cv2.getTextSize(t, OSD_FONT, scale, thickness)[0][0] for t in lines)
        box_bottom = top + (len(lines) - 1) * line_px + line_px // 3
        cv2.rectangle(image, (left - 8, top - line_px), (left + text_w + 4, box_bottom), 0, -1)
        bar = CAMERA_BAR_BGR[camera % len(CAMERA_BAR_BGR)]
        cv2.rectangle(image, (left - 8, top - line_px), (left - 3, box_bottom), bar, -1)
        for index, text in enumerate(lines):
            origin = (left, top + index * line_px)
            cv2.putText(
                image, text, origin, OSD_FONT, scale, OSD_COLOUR_BGR, thickness, cv2.LINE_AA
            )


class Battery:
    """A pack that drains with time, faster while the robot moves."""

    def __init__(self, percent: float, drain_percent_per_s: float) -> None:
        self.percent = min(max(percent, 0.0), 100.0)
        self.drain_percent_per_s = drain_percent_per_s

    def step(self, dt_s: float, moving: bool) -> None:
        """Drain for dt_s seconds."""
        factor = MOTION_DRAIN_FACTOR if moving else 1.0
        self.percent = max(0.0, self.percent - self.drain_percent_per_s * factor * dt_s)

    @property
    def voltage_v(self) -> float:
        """Terminal voltage: linear between the empty and the full voltage."""
        return BATTERY_EMPTY_V + (BATTERY_FULL_V - BATTERY_EMPTY_V) * self.percent / 100.0


@dataclass
class _Stream:
    request: CameraRequest
    next_due_s: float
    sent: int = 0


@dataclass(frozen=True)
class ExtendedCounters:
    """What the extended side has sent."""

    client: tuple[str, int] | None
    active: bool
    hellos: int
    status_sent: int
    scans_sent: int
    fragments_sent: int
    frames_sent: tuple[int, ...]
    corrupt_sent: int
    battery_percent: float
    requests: tuple[CameraRequest, ...]
    stopped_cameras: tuple[int, ...]


class ExtendedServer:
    """Extension state of one simulator; called from the simulator's loop thread only,
    except for the settings methods (stop_camera, set_battery, set_corrupt) which lock.
    """

    def __init__(
        self,
        profile: RobotProfile,
        codec: ExtendedCodec,
        *,
        status_hz: float = DEFAULT_STATUS_HZ,
        battery_percent: float = 100.0,
        drain_percent_per_s: float = DEFAULT_DRAIN_PERCENT_PER_S,
        corrupt: float = 0.0,
        seed: int | None = None,
        world: WorldView | None = None,
        range_sensor: RangeSensor | None = None,
        imu_noise_rad: float = IMU_NOISE_RAD,
    ) -> None:
        if not (math.isfinite(status_hz) and status_hz > 0.0):
            raise ValueError(f"status_hz must be > 0, got {status_hz!r}")
        self.profile = profile
        self.codec = codec
        self.cameras = SyntheticCameras(profile.cameras, world)
        # Scans go out only where the extension has a scan packet type.
        self.range_sensor = range_sensor if codec.scan_type is not None else None
        self._scan_period_s = (
            1.0 / self.range_sensor.config.scan_hz if self.range_sensor is not None else math.inf
        )
        self._next_scan_s = math.inf
        self._scans_sent = 0
        self._imu_noise_rad = imu_noise_rad
        self._imu_rng = random.Random(seed)
        self.watchdog_s = profile.link.robot_watchdog_s
        self._status_period_s = 1.0 / status_hz
        self._lock = threading.Lock()
        self._battery = Battery(battery_percent, drain_percent_per_s)
        self._corrupt = corrupt
        self._stopped: set[int] = set()
        self._rng = random.Random(seed)
        self._client: tuple[str, int] | None = None
        self._last_hello_s = -math.inf
        self._max_datagram = 1472
        self._streams: dict[int, _Stream] = {}
        # Per camera for the robot's whole run (docs/protocol.md): a stream that stops and
        # starts again on a fresh hello goes on counting, so the OCU never sees it go back.
        self._video_sequences = [0] * len(profile.cameras)
        self._next_status_s = math.inf
        self._status_sequence = 0
        self._last_step_s: float | None = None
        self._hellos = 0
        self._status_sent = 0
        self._fragments_sent = 0
        self._frames_sent = [0] * len(profile.cameras)
        self._corrupt_sent = 0

    # ---- settings (any thread) -------------------------------------------------------------

    def stop_camera(self, camera: int) -> None:
        """Make a camera fall silent (a failed camera) until resume_camera()."""
        with self._lock:
            self._stopped.add(camera)

    def resume_camera(self, camera: int) -> None:
        """End a stop_camera()."""
        with self._lock:
            self._stopped.discard(camera)

    def set_battery(self, percent: float) -> None:
        """Set the charge (0-100 %)."""
        with self._lock:
            self._battery.percent = min(max(percent, 0.0), 100.0)

    def set_corrupt(self, probability: float) -> None:
        """Probability that a frame's JPEG is sent corrupt (header destroyed)."""
        if not (math.isfinite(probability) and 0.0 <= probability <= 1.0):
            raise ValueError(f"corrupt must be a probability, got {probability!r}")
        with self._lock:
            self._corrupt = probability

    # ---- loop thread -----------------------------------------------------------------------

    def active(self, now_s: float) -> bool:
        """Whether a client said hello within the watchdog time."""
        return self._client is not None and now_s - self._last_hello_s <= self.watchdog_s

    def on_hello(self, hello: HelloPacket, address: tuple[str, int], now_s: float) -> None:
        """Take a hello: (re)start streaming to its sender as it asks."""
        self._hellos += 1
        fresh = not self.active(now_s) or address != self._client
        self._client = address
        self._last_hello_s = now_s
        self._max_datagram = hello.max_datagram_bytes
        wanted = {r.camera: r for r in hello.cameras if 0 <= r.camera < len(self.cameras.cameras)}
        for camera in list(self._streams):
            if camera not in wanted:
                del self._streams[camera]
        for camera, asked in wanted.items():
            request = self._clamp(asked)
            stream = self._streams.get(camera)
            if stream is None or fresh:
                # Stagger the cameras so their frames do not all fall due at once.
                phase_s = camera / max(len(wanted), 1) / max(request.fps, 1)
                self._streams[camera] = _Stream(request, now_s + phase_s)
            elif stream.request != request:
                stream.request = request
        if fresh:
            self._next_status_s = now_s  # answer at once: the OCU detects the extension
            if self.range_sensor is not None:
                self._next_scan_s = now_s

    def next_due_s(self) -> float:
        """When poll() next has something to send."""
        if self._client is None:
            return math.inf
        due = [self._next_status_s, self._next_scan_s, self._last_hello_s + self.watchdog_s]
        due.extend(s.next_due_s for s in self._streams.values() if s.request.fps > 0)
        return min(due)

    def poll(
        self,
        now_s: float,
        send: Callable[[bytes, tuple[str, int]], None],
        *,
        torch: bool,
        pose: tuple[float, float, float],
        moving: bool,
        rcp_quality: int,
        joints_rad: Mapping[str, float] | None = None,
        rcp_echo: tuple[int, int] | None = None,
    ) -> None:
        """Drain the battery; send whatever is due: status packets and camera frames.

        `rcp_echo` is the newest sequenced RCP applied and how many were (status version 3).
        """
        if self._last_step_s is not None:
            with self._lock:
                self._battery.step(max(0.0, now_s - self._last_step_s), moving)
        self._last_step_s = now_s
        if not self.active(now_s):
            if self._client is not None:
                self._client = None
                self._streams.clear()
                self._next_status_s = math.inf
                self._next_scan_s = math.inf
            return
        client = self._client
        assert client is not None
        if now_s >= self._next_status_s:
            self._next_status_s = max(self._next_status_s + self._status_period_s, now_s)
            send(self.codec.encode(self._status(torch, pose, rcp_echo)), client)
            self._status_sent += 1
        if self.range_sensor is not None and now_s >= self._next_scan_s:
            self._next_scan_s = max(self._next_scan_s + self._scan_period_s, now_s)
            scan = self.range_sensor.sweep(Pose(*pose), int(time.monotonic() * 1_000_000))
            send(self.codec.encode(scan), client)
            self._scans_sent += 1
        with self._lock:
            stopped = set(self._stopped)
            corrupt = self._corrupt
        for camera, stream in self._streams.items():
            fps = stream.request.fps
            if fps <= 0 or now_s < stream.next_due_s:
                continue
            period_s = 1.0 / fps
            stream.next_due_s += period_s
            if stream.next_due_s <= now_s:
                stream.next_due_s = now_s + period_s  # skip a backlog rather than burst
            if camera in stopped:
                continue
            jpeg, capture_s = self._render(
                camera, stream, torch, rcp_quality, Pose(*pose), joints_rad=joints_rad
            )
            self._send_frame(stream, jpeg, capture_s, corrupt, lambda d: send(d, client))

    def _render(
        self,
        camera: int,
        stream: _Stream,
        torch: bool,
        rcp_quality: int,
        pose: Pose,
        *,
        joints_rad: Mapping[str, float] | None = None,
    ) -> tuple[bytes, float]:
        request = stream.request
        capture_s = time.monotonic()
        jpeg = self.cameras.render(
            camera,
            (request.width_px, request.height_px),
            self._video_sequences[camera],
            capture_s,
            request.quality or rcp_quality,
            torch=torch,
            pose=pose,
            joints_rad=joints_rad,
        )
        return jpeg, capture_s

    def _send_frame(
        self,
        stream: _Stream,
        jpeg: bytes,
        capture_s: float,
        corrupt: float,
        send: Callable[[bytes], None],
    ) -> None:
        if corrupt > 0.0 and self._rng.random() < corrupt:
            # Keep SOI and EOI (the codec's checks pass) but destroy every header.
            jpeg = jpeg[:3] + bytes(self._rng.getrandbits(8) for _ in range(64)) + jpeg[-2:]
            self._corrupt_sent += 1
        camera = stream.request.camera
        sequence = self._video_sequences[camera]
        fragments = fragment_frame(
            camera, sequence, int(capture_s * 1_000_000), jpeg, self._max_datagram
        )
        for fragment in fragments:
            send(self.codec.encode(fragment))
        self._fragments_sent += len(fragments)
        self._frames_sent[camera] += 1
        self._video_sequences[camera] = (sequence + 1) % 2**32
        stream.sent += 1

    def _status(
        self, torch: bool, pose: tuple[float, float, float], rcp_echo: tuple[int, int] | None
    ) -> StatusPacket:
        x_m, y_m, heading = pose
        # Terrain slopes along world x and y, seen in the robot's frame.
        slope_x = TERRAIN_PITCH_RAD * math.sin(2 * math.pi * x_m / TERRAIN_WAVELENGTH_M)
        slope_y = TERRAIN_ROLL_RAD * math.sin(2 * math.pi * y_m / TERRAIN_WAVELENGTH_M)
        pitch = slope_x * math.cos(heading) + slope_y * math.sin(heading)
        roll = -slope_x * math.sin(heading) + slope_y * math.cos(heading)
        with self._lock:
            percent = self._battery.percent
            voltage = self._battery.voltage_v
        self._status_sequence = (self._status_sequence + 1) % 2**32
        return StatusPacket(
            sequence=self._status_sequence,
            voltage_mv=round(voltage * 1000),
            charge_permille=round(percent * 10),
            headlight_on=torch,
            roll_mrad=round(roll * 1000),
            pitch_mrad=round(pitch * 1000),
            camera_count=len(self.cameras.cameras),
            # The IMU's heading: the true one with a little noise (its zero is the world's).
            yaw_mrad=round(self._imu_heading(heading) * 1000),
            rcp_sequence=None if rcp_echo is None else rcp_echo[0],
            rcp_received=None if rcp_echo is None else rcp_echo[1],
        )

    def _imu_heading(self, heading_rad: float) -> float:
        noise = self._imu_rng.gauss(0.0, self._imu_noise_rad) if self._imu_noise_rad else 0.0
        return math.remainder(heading_rad + noise, math.tau)

    def _clamp(self, request: CameraRequest) -> CameraRequest:
        return CameraRequest(
            camera=request.camera,
            width_px=min(max(request.width_px, MIN_FRAME_SIDE_PX), MAX_FRAME_SIDE_PX),
            height_px=min(max(request.height_px, MIN_FRAME_SIDE_PX), MAX_FRAME_SIDE_PX),
            fps=min(request.fps, MAX_FPS),
            quality=request.quality,
        )

    def counters(self, now_s: float) -> ExtendedCounters:
        """A snapshot of what was sent."""
        with self._lock:
            percent = self._battery.percent
            stopped = tuple(sorted(self._stopped))
        return ExtendedCounters(
            client=self._client,
            active=self.active(now_s),
            hellos=self._hellos,
            status_sent=self._status_sent,
            scans_sent=self._scans_sent,
            fragments_sent=self._fragments_sent,
            frames_sent=tuple(self._frames_sent),
            corrupt_sent=self._corrupt_sent,
            battery_percent=percent,
            requests=tuple(s.request for s in self._streams.values()),
            stopped_cameras=stopped,
        )
