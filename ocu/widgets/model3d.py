"""3D model of the robot: live pose from telemetry, a ghost of the targets, stale joints amber.

The widget draws with OpenGL in a QOpenGLWidget when the display has GL, and otherwise with
the same renderer in an OSMesa context, showing the image in a plain QWidget. The mouse
works the same in both: left drag orbits, middle drag or Shift+left drag pans, the wheel
zooms, a double click resets the view; 1/2/3/4 (or the context menu) pick preset views.

For the arm it draws the tool frame (tool0's axes, through the gripper), the jog's direction
as an arrow, a pose goal's marker, and on request the reachable workspace in the arm's plane
as translucent cells; Ctrl+click picks a point on the horizontal plane at `pick_height_m`
(the pose goal's height) and emits `point_picked`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from functools import partial
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt
from PySide6.QtCore import QPointF, Qt, QTimer, Signal, Slot
from PySide6.QtGui import (
    QContextMenuEvent,
    QGuiApplication,
    QImage,
    QKeyEvent,
    QMouseEvent,
    QWheelEvent,
)
from PySide6.QtWidgets import QMenu, QVBoxLayout, QWidget

from ocu.model.mesh import MeshData
from ocu.model.tree import KinematicTree, Matrix
from ocu.model.urdf import RobotModel, load_urdf, profile_urdf_path
from ocu.profile import RobotProfile
from ocu.records import JointReading
from ocu.render.camera import VIEW_KEYS, VIEWS, OrbitCamera
from ocu.render.overlays import arrow_mesh, axes_mesh, marker_mesh
from ocu.render.platform import GlMode, choose_gl_platform, configure_gl_platform
from ocu.render.scene import OverlayDraw, RenderFrame, build_frame, model_bounds
from ocu.widgets.model3d_surfaces import GlSurface, SoftwareSurface

FRESHNESS_CHECK_MS = 250
WORKSPACE_ALPHA = 0.13
# The jog arrow: this long at the jog's full speed, never shorter than the minimum.
ARROW_M_PER_M_S = 3.0
ARROW_MIN_M = 0.08
# A joint moving less than this is not drawn again: 0.01°, a tenth of a millimetre at the
# tip of a metre-long arm (the prediction wanders by less at every telemetry frame).
REDRAW_EPSILON_RAD = 2e-4


class TelemetryFrameLike(Protocol):
    """What on_telemetry reads from a telemetry frame (ocu.records.TelemetryFrame)."""

    @property
    def readings(self) -> Mapping[str, JointReading]: ...

    @property
    def received_at(self) -> float: ...


class _Surface(Protocol):
    """The child that shows the picture: GL widget or OSMesa image."""

    frames_rendered: int
    error: str | None

    def request_render(self) -> None: ...

    def render_now(self) -> None: ...

    def release(self) -> None: ...


class Model3DWidget(QWidget):
    """The robot in 3D, following telemetry; see the module docstring for the controls."""

    frame_rendered = Signal()
    # A point picked with Ctrl+click: x, y on the plane z = pick_height_m (base frame, m).
    point_picked = Signal(float, float, float)

    def __init__(
        self,
        profile: RobotProfile,
        urdf_path: str | Path | None = None,
        parent: QWidget | None = None,
        *,
        stale_after_s: float | None = None,
        gl_mode: GlMode | None = None,
    ) -> None:
        super().__init__(parent)
        self.profile = profile
        self.model: RobotModel = load_urdf(
            urdf_path if urdf_path is not None else profile_urdf_path(profile)
        )
        self.live: KinematicTree = self.model.tree.copy()
        self.ghost: KinematicTree | None = None
        self._ghost_targets: dict[str, float] = {}
        # The pose of the last reading (drawn faintly behind the predicted pose) and the
        # joints whose reading is implausible (drawn red).
        self.reading: KinematicTree | None = None
        self._faults: frozenset[str] = frozenset()
        self.stale_after_s = (
            profile.link.link_lost_after_s if stale_after_s is None else stale_after_s
        )
        # Joints that telemetry can refresh: in both the profile and the model.
        self.tracked_joints = frozenset(
            name
            for name, motor in profile.motors.items()
            if motor.has_position and name in self.live.actuated_joints
        )
        self._fresh_at: dict[str, float] = {}
        self._marked_stale: set[str] = set()
        self._drawn_stale: frozenset[str] = self.stale_joints()  # nothing heard yet
        low, high = model_bounds(self.model, self.live)
        self.camera = OrbitCamera.framing(low, high, "iso")
        self._drag_button: Qt.MouseButton | None = None
        self._drag_pan = False
        self._last_pos = QPointF()
        # The arm's helpers: the tool frame (a link of the model), the jog's direction, a
        # goal's pose, the workspace cells (drawn with a link's transform).
        arm = profile.arm
        self.tool_link = (
            arm.tool_link if arm is not None and arm.tool_link in self.live.links else None
        )
        self._jog: npt.NDArray[np.float64] | None = None
        self._goal_pose: Matrix | None = None
        self._workspace_link: str | None = None
        self.workspace_visible = False
        self.pick_height_m = 0.3
        self._overlay_meshes: dict[str, tuple[MeshData, str]] = {
            "axes": (axes_mesh(), "lines"),
            "arrow": (arrow_mesh(), "lines"),
            "goal": (marker_mesh(), "lines"),
        }

        wanted = gl_mode or choose_gl_platform(qt_platform=QGuiApplication.platformName())
        self.gl_mode: GlMode = configure_gl_platform(wanted)
        surface: _Surface = GlSurface(self) if self.gl_mode == "native" else SoftwareSurface(self)
        self._surface = surface
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        assert isinstance(surface, QWidget)
        surface.setAttribute(Qt.WidgetAttribute.WA_TransparentForMouseEvents)
        layout.addWidget(surface)
        self.setFocusPolicy(Qt.FocusPolicy.StrongFocus)
        self.setMinimumSize(160, 120)

        self._freshness_timer = QTimer(self)
        self._freshness_timer.setInterval(FRESHNESS_CHECK_MS)
        self._freshness_timer.timeout.connect(self._check_freshness)
        self._freshness_timer.start()

    # State in.

    def set_joint_angles(
        self, angles_rad: Mapping[str, float], fresh_at: float | None = None
    ) -> None:
        """Show these joint angles; `fresh_at` (monotonic, default now) marks them fresh.

        Names the model does not have (the tracks, another robot's joints) and non-finite
        values are ignored.
        """
        stamp = time.monotonic() if fresh_at is None else fresh_at
        changed = False
        for name, value in angles_rad.items():
            if name not in self.live.actuated_joints or not math.isfinite(value):
                continue
            if abs(self.live.position(name) - value) > REDRAW_EPSILON_RAD:
                self.live.set_position(name, value)
                changed = True
            if name in self.tracked_joints:
                self._fresh_at[name] = max(stamp, self._fresh_at.get(name, -math.inf))
                self._marked_stale.discard(name)
        if changed:
            self._update_ghost()
        self._check_freshness(force=changed)

    @Slot(object)
    def on_telemetry(self, frame: TelemetryFrameLike) -> None:
        """Follow a telemetry frame: every motor with a position sets its joint."""
        angles = {
            name: reading.angle_rad
            for name, reading in frame.readings.items()
            if reading.angle_rad is not None
        }
        self.set_joint_angles(angles, fresh_at=frame.received_at)

    def show_reading(self, frame: TelemetryFrameLike) -> None:
        """Where the last reading put each joint, drawn faintly behind the live pose.

        The live pose is the predicted one (set_joint_angles): under delay the last reading
        shows the past, and the operator should not steer by it. Joints whose reading is
        implausible are drawn red and keep their last believable pose.
        """
        angles = {
            name: reading.angle_rad
            for name, reading in frame.readings.items()
            if reading.angle_rad is not None
            and reading.fault is None
            and name in self.live.actuated_joints
            and math.isfinite(reading.angle_rad)
        }
        faults = frozenset(
            name
            for name, reading in frame.readings.items()
            if reading.fault is not None and name in self.live.joints
        )
        if self.reading is None:
            self.reading = self.live.copy()
        elif faults == self._faults and all(
            abs(self.reading.position(name) - value) <= REDRAW_EPSILON_RAD
            for name, value in angles.items()
        ):
            return  # nothing the eye could see moved
        self.reading.set_positions(angles)
        self._faults = faults
        self.request_render()

    @property
    def fault_joints(self) -> frozenset[str]:
        """Joints drawn red: their reading is implausible."""
        return self._faults

    def set_ghost(self, targets_rad: Mapping[str, float] | None) -> None:
        """Show a translucent robot at these targets (None or empty: no ghost)."""
        self._ghost_targets = {
            name: value
            for name, value in (targets_rad or {}).items()
            if name in self.live.actuated_joints and math.isfinite(value)
        }
        self._update_ghost()
        self.request_render()

    def mark_stale(self, names: set[str]) -> None:
        """Draw these joints in the warning colour until fresh telemetry arrives for them."""
        self._marked_stale.update(name for name in names if name in self.live.joints)
        self._check_freshness(force=True)

    def stale_joints(self, now: float | None = None) -> frozenset[str]:
        """Joints without telemetry newer than stale_after_s, plus those marked stale."""
        moment = time.monotonic() if now is None else now
        old = {
            name
            for name in self.tracked_joints
            if moment - self._fresh_at.get(name, -math.inf) > self.stale_after_s
        }
        return frozenset(old | self._marked_stale)

    @property
    def drawn_stale_joints(self) -> frozenset[str]:
        """The stale set the picture was last asked to show."""
        return self._drawn_stale

    @property
    def ghost_targets(self) -> dict[str, float]:
        """The targets the ghost shows (empty: none)."""
        return dict(self._ghost_targets)

    def _update_ghost(self) -> None:
        if not self._ghost_targets:
            self.ghost = None
            return
        ghost = self.live.copy()
        ghost.set_positions(self._ghost_targets)
        self.ghost = ghost

    def _check_freshness(self, force: bool = False) -> None:
        stale = self.stale_joints()
        if force or stale != self._drawn_stale:
            self._drawn_stale = stale
            self.request_render()

    # The arm's helpers.

    def set_jog_direction(self, twist: npt.ArrayLike | None) -> None:
        """The jog's velocity in the base frame (vx, vy, vz m/s, pitch rad/s), None: no jog."""
        self._jog = None if twist is None else np.asarray(twist, dtype=np.float64)
        self.request_render()

    def set_goal_pose(self, pose: Matrix | None) -> None:
        """Where a goal puts the tool (a 4x4 in the base frame), None: no goal."""
        self._goal_pose = None if pose is None else np.asarray(pose, dtype=np.float64)
        self.request_render()

    def set_workspace(self, link: str | None, mesh: MeshData | None) -> None:
        """The workspace cells, drawn with a link's transform (None: this arm has none)."""
        self._workspace_link = link if link in self.live.links else None
        if mesh is not None:
            self.set_overlay_mesh("workspace", mesh, "triangles")
        self.request_render()

    def set_workspace_visible(self, visible: bool) -> None:
        """Draw the workspace or not."""
        self.workspace_visible = visible
        self.request_render()

    def set_overlay_mesh(self, name: str, mesh: MeshData, mode: str) -> None:
        """A helper mesh the frames may draw (uploaded once, at the next frame)."""
        self._overlay_meshes[name] = (mesh, mode)
        renderer = getattr(self._surface, "renderer", None)
        if renderer is not None:
            lock = getattr(self._surface, "render_lock", None)
            if lock is None:
                renderer.set_overlay_mesh(name, mesh, mode)
            else:
                with lock:  # the render thread reads the renderer's pending meshes
                    renderer.set_overlay_mesh(name, mesh, mode)

    def install_overlays(self, renderer: Any) -> None:
        """Give a new renderer every helper mesh."""
        for name, (mesh, mode) in self._overlay_meshes.items():
            renderer.set_overlay_mesh(name, mesh, mode)

    def overlays(self) -> list[OverlayDraw]:
        """The helpers to draw now."""
        items: list[OverlayDraw] = []
        world = self.live.world_transforms()
        if self.workspace_visible and self._workspace_link is not None:
            items.append(
                OverlayDraw("workspace", world[self._workspace_link].copy(), WORKSPACE_ALPHA)
            )
        if self.tool_link is not None:
            tool = world[self.tool_link].copy()
            items.append(OverlayDraw("axes", tool, on_top=True))
            if self._jog is not None:
                items.append(OverlayDraw("arrow", _arrow(tool, self._jog), on_top=True))
        if self._goal_pose is not None:
            items.append(OverlayDraw("goal", self._goal_pose.copy(), on_top=True))
            items.append(OverlayDraw("axes", self._goal_pose.copy(), alpha=0.6, on_top=True))
        return items

    # View.

    def set_view(self, name: str) -> None:
        """Preset direction: front, side, top or iso."""
        self.camera.set_view(name)
        self.request_render()

    def reset_view(self) -> None:
        """Frame the robot as it stands now (and its ghost), from the iso direction."""
        low, high = model_bounds(self.model, self.live)
        if self.ghost is not None:
            ghost_low, ghost_high = model_bounds(self.model, self.ghost)
            low, high = np.minimum(low, ghost_low), np.maximum(high, ghost_high)
        self.camera.reframe(low, high, "iso")
        self.request_render()

    # Drawing.

    @property
    def frames_rendered(self) -> int:
        """Frames drawn so far (either path)."""
        return self._surface.frames_rendered

    @property
    def render_error(self) -> str | None:
        """Why nothing can be drawn, or None."""
        return self._surface.error

    @property
    def drawn_through(self) -> str:
        """Which GL path draws: 'the display's OpenGL', or the offscreen one with its renderer
        (e.g. 'EGL (llvmpipe ...)') once it has drawn."""
        offscreen = getattr(self._surface, "_offscreen", None)
        if offscreen is not None:
            return str(offscreen.describe())
        return "the display's OpenGL" if self.gl_mode == "native" else self.gl_mode

    @property
    def buffer_uploads(self) -> int:
        """Vertex buffer uploads so far: one per mesh, at the first frame, never again."""
        renderer = getattr(self._surface, "renderer", None)
        return int(getattr(renderer, "buffer_uploads", 0))

    def request_render(self) -> None:
        """Schedule a redraw (rate-limited on the OSMesa path)."""
        self._surface.request_render()

    def render_now(self) -> None:
        """Draw at once (before grab() of the OSMesa path, for screenshots)."""
        self._surface.render_now()

    def build_frame(self, width_px: int, height_px: int) -> RenderFrame:
        """The frame for the current state at a given size."""
        return build_frame(
            self.model,
            self.camera,
            width_px / max(height_px, 1),
            live=self.live,
            ghost=self.ghost,
            stale_joints=self._drawn_stale,
            reading=self.reading,
            fault_joints=self._faults,
            overlays=self.overlays(),
        )

    def _surface_rendered(self) -> None:
        self.frame_rendered.emit()

    def release(self) -> None:
        """Free the GL resources now (also done when the widget is destroyed)."""
        self._freshness_timer.stop()
        self._surface.release()

    # Mouse and keys.

    def mousePressEvent(self, event: QMouseEvent) -> None:
        """Start an orbit (left) or pan (middle, Shift+left) drag."""
        button = event.button()
        shift = bool(event.modifiers() & Qt.KeyboardModifier.ShiftModifier)
        control = bool(event.modifiers() & Qt.KeyboardModifier.ControlModifier)
        if button == Qt.MouseButton.LeftButton and control:
            self.pick(event.position().x(), event.position().y())
            event.accept()
            return
        if button in (Qt.MouseButton.LeftButton, Qt.MouseButton.MiddleButton):
            self._drag_button = button
            self._drag_pan = button == Qt.MouseButton.MiddleButton or shift
            self._last_pos = event.position()
            event.accept()
            return
        super().mousePressEvent(event)

    def pick(self, x_px: float, y_px: float) -> npt.NDArray[np.float64] | None:
        """The point under a pixel on the plane z = pick_height_m; emits point_picked."""
        point = self.camera.pick_on_height(
            x_px, y_px, max(self.width(), 1), max(self.height(), 1), self.pick_height_m
        )
        if point is not None:
            self.point_picked.emit(float(point[0]), float(point[1]), float(point[2]))
        return point

    def mouseMoveEvent(self, event: QMouseEvent) -> None:
        """Orbit or pan by the distance moved since the last event."""
        if self._drag_button is None:
            super().mouseMoveEvent(event)
            return
        position = event.position()
        dx = position.x() - self._last_pos.x()
        dy = position.y() - self._last_pos.y()
        self._last_pos = position
        if self._drag_pan:
            self.camera.pan(dx, dy, max(self.height(), 1))
        else:
            self.camera.orbit(dx, dy)
        self.request_render()
        event.accept()

    def mouseReleaseEvent(self, event: QMouseEvent) -> None:
        """End the drag."""
        if event.button() == self._drag_button:
            self._drag_button = None
            event.accept()
            return
        super().mouseReleaseEvent(event)

    def mouseDoubleClickEvent(self, event: QMouseEvent) -> None:
        """Reset the view."""
        if event.button() == Qt.MouseButton.LeftButton:
            self.reset_view()
            event.accept()
            return
        super().mouseDoubleClickEvent(event)

    def wheelEvent(self, event: QWheelEvent) -> None:
        """Zoom: one notch (120 units) is one step."""
        steps = event.angleDelta().y() / 120.0
        if steps:
            self.camera.zoom(steps)
            self.request_render()
        event.accept()

    def keyPressEvent(self, event: QKeyEvent) -> None:
        """1-4: front, side, top, iso views; Home: reset."""
        text = event.text().lower()
        if text in VIEW_KEYS:
            self.set_view(VIEW_KEYS[text])
        elif event.key() == Qt.Key.Key_Home:
            self.reset_view()
        else:
            super().keyPressEvent(event)

    def contextMenuEvent(self, event: QContextMenuEvent) -> None:
        """Preset views and reset."""
        menu = QMenu(self)
        for name in VIEWS:
            menu.addAction(name.capitalize(), partial(self.set_view, name))
        menu.addSeparator()
        menu.addAction("Reset view", self.reset_view)
        menu.exec(event.globalPos())


def _arrow(tool: Matrix, twist: npt.NDArray[np.float64]) -> Matrix:
    """The arrow's transform: from tool0 along the jog's direction, its length its speed."""
    linear = twist[:3]
    speed = float(np.linalg.norm(linear))
    if speed < 1e-9:
        # A pitch alone: a short arrow along the tool's z, up or down.
        direction = tool[:3, 2] * (1.0 if twist[3] >= 0.0 else -1.0)
        length = ARROW_MIN_M
    else:
        direction = linear / speed
        length = max(speed * ARROW_M_PER_M_S, ARROW_MIN_M)
    helper = np.array([0.0, 0.0, 1.0]) if abs(direction[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    side = np.cross(helper, direction)
    side /= np.linalg.norm(side)
    up = np.cross(direction, side)
    result = np.eye(4)
    result[:3, 0] = direction * length
    result[:3, 1] = side * length
    result[:3, 2] = up * length
    result[:3, 3] = tool[:3, 3]
    return result


def image_array(image: QImage) -> np.ndarray[Any, np.dtype[np.uint8]]:
    """A QImage as an (h, w, 4) RGBA array (for tests and screenshots)."""
    converted = image.convertToFormat(QImage.Format.Format_RGBA8888)
    width, height = converted.width(), converted.height()
    buffer = np.frombuffer(converted.constBits(), dtype=np.uint8)
    rows = buffer[: converted.bytesPerLine() * height].reshape(height, converted.bytesPerLine())
    return rows[:, : width * 4].reshape(height, width, 4).copy()
