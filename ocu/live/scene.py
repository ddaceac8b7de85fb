"""What Foxglove's 3D panel draws better with its own schema: the console's safety zones, the
planned path and the arm's goal as `foxglove_msgs/msg/SceneUpdate` (docs/live.md).

The server's other channels are ROS 2 messages in CDR with `ros2msg` schemas, and so are these:
Foxglove and Lichtblick take the SceneUpdate in any of its encodings (ROS 1, ROS 2, JSON,
Protobuf) and decode it with the schema the server advertises, so one encoding serves every
channel. The definitions are the foxglove_msgs ones Foxglove and Lichtblick know.

- `/scene/zones` (in `base_link`, frame locked: the rings move with the robot): one closed
  line per zone, the footprint grown by the zone's distance, stop zone first, as the map
  draws them; faint while the zones are off, the zone limiting the drive drawn thicker. The
  entity's metadata carry the status bar's words.
- `/scene/plan` (in `odom`): the path the path mode drives, or the shuttle's two points.
- `/scene/arm_goal` (in the arm's base link): the target frame of the goal the console shows
  (a preview before Accept, or the move under way) as three axes and its label.

Each is sent when it changes (checked every SCENE_PERIOD_S on the server's thread) and kept
for a client that subscribes later; an entity that is gone is deleted by id. The model is
read without the control core's lock: the arm's goal is an immutable record swapped whole,
the zones and the path are read under the navigator's own lock.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, Final, Protocol

import numpy as np

from ocu.console.arm import ArmGoal
from ocu.live.robot import quaternion_xyzw
from ocu.nav.messages import BASE_FRAME, ODOM_FRAME
from ocu.nav.navigator import ZoneState
from ocu.profile import Footprint, RobotProfile, ZoneSettings
from ocu.record import schemas as s

ZONES: Final = "/scene/zones"
PLAN: Final = "/scene/plan"
ARM_GOAL: Final = "/scene/arm_goal"
SCENE_PERIOD_S: Final = 0.05
# Points per quarter circle of a zone's rounded corner.
CORNER_STEPS: Final = 6
LINE_LOOP: Final = 1
LINE_STRIP: Final = 0
MATCHING_ID: Final = 0
ZONE_LINE_M: Final = 0.015
LIMITING_LINE_M: Final = 0.04
PATH_LINE_M: Final = 0.03
AXIS_LENGTH_M: Final = 0.12
# Stop zone first, then each zone outward (the map's colours).
ZONE_RGB: Final = ((0.83, 0.18, 0.18), (0.96, 0.49, 0.0), (0.98, 0.75, 0.18), (0.49, 0.70, 0.26))
PATH_RGBA: Final = (0.1, 0.46, 0.82, 1.0)
# The goal's axes: x red, y green, z blue; a preview fainter than a move under way.
AXIS_RGB: Final = ((0.9, 0.1, 0.1), (0.1, 0.8, 0.1), (0.1, 0.3, 0.95))

_TIME = "int32 sec\nuint32 nanosec\n"
_POINT = "float64 x\nfloat64 y\nfloat64 z\n"
_QUATERNION = "float64 x\nfloat64 y\nfloat64 z\nfloat64 w\n"
_COLOR = "float64 r\nfloat64 g\nfloat64 b\nfloat64 a\n"
_POSE_FIELDS = "geometry_msgs/Pose pose\n"

SCENE_UPDATE = s.MessageType(
    "foxglove_msgs/msg/SceneUpdate",
    s.concatenate(
        "foxglove_msgs/SceneEntityDeletion[] deletions\nfoxglove_msgs/SceneEntity[] entities\n",
        (
            "foxglove_msgs/SceneEntityDeletion",
            "builtin_interfaces/Time timestamp\nuint8 MATCHING_ID=0\nuint8 ALL=1\nuint8 type\n"
            "string id\n",
        ),
        ("builtin_interfaces/Time", _TIME),
        (
            "foxglove_msgs/SceneEntity",
            "builtin_interfaces/Time timestamp\nstring frame_id\nstring id\n"
            "builtin_interfaces/Duration lifetime\nbool frame_locked\n"
            "foxglove_msgs/KeyValuePair[] metadata\nfoxglove_msgs/ArrowPrimitive[] arrows\n"
            "foxglove_msgs/CubePrimitive[] cubes\nfoxglove_msgs/SpherePrimitive[] spheres\n"
            "foxglove_msgs/CylinderPrimitive[] cylinders\nfoxglove_msgs/LinePrimitive[] lines\n"
            "foxglove_msgs/TriangleListPrimitive[] triangles\n"
            "foxglove_msgs/TextPrimitive[] texts\nfoxglove_msgs/ModelPrimitive[] models\n",
        ),
        ("builtin_interfaces/Duration", _TIME),
        ("foxglove_msgs/KeyValuePair", "string key\nstring value\n"),
        (
            "foxglove_msgs/ArrowPrimitive",
            _POSE_FIELDS + "float64 shaft_length\nfloat64 shaft_diameter\nfloat64 head_length\n"
            "float64 head_diameter\nfoxglove_msgs/Color color\n",
        ),
        ("geometry_msgs/Pose", "Point position\nQuaternion orientation\n"),
        ("geometry_msgs/Point", _POINT),
        ("geometry_msgs/Quaternion", _QUATERNION),
        ("foxglove_msgs/Color", _COLOR),
        (
            "foxglove_msgs/CubePrimitive",
            _POSE_FIELDS + "geometry_msgs/Vector3 size\nfoxglove_msgs/Color color\n",
        ),
        ("geometry_msgs/Vector3", _POINT),
        (
            "foxglove_msgs/SpherePrimitive",
            _POSE_FIELDS + "geometry_msgs/Vector3 size\nfoxglove_msgs/Color color\n",
        ),
        (
            "foxglove_msgs/CylinderPrimitive",
            _POSE_FIELDS + "geometry_msgs/Vector3 size\nfloat64 bottom_scale\nfloat64 top_scale\n"
            "foxglove_msgs/Color color\n",
        ),
        (
            "foxglove_msgs/LinePrimitive",
            "uint8 LINE_STRIP=0\nuint8 LINE_LOOP=1\nuint8 LINE_LIST=2\nuint8 type\n"
            + _POSE_FIELDS
            + "float64 thickness\nbool scale_invariant\ngeometry_msgs/Point[] points\n"
            "foxglove_msgs/Color color\nfoxglove_msgs/Color[] colors\nuint32[] indices\n",
        ),
        (
            "foxglove_msgs/TriangleListPrimitive",
            _POSE_FIELDS + "geometry_msgs/Point[] points\nfoxglove_msgs/Color color\n"
            "foxglove_msgs/Color[] colors\nuint32[] indices\n",
        ),
        (
            "foxglove_msgs/TextPrimitive",
            _POSE_FIELDS + "bool billboard\nfloat64 font_size\nbool scale_invariant\n"
            "foxglove_msgs/Color color\nstring text\n",
        ),
        (
            "foxglove_msgs/ModelPrimitive",
            _POSE_FIELDS + "geometry_msgs/Vector3 scale\nfoxglove_msgs/Color color\n"
            "bool override_color\nstring url\nstring media_type\nuint8[] data\n",
        ),
    ),
)


class SceneModel(Protocol):
    """What the scene reads of the console model."""

    @property
    def arm(self) -> Any: ...

    @property
    def nav(self) -> Any: ...


_IDENTITY = {
    "position": {"x": 0.0, "y": 0.0, "z": 0.0},
    "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
}


def _color(rgba: Sequence[float]) -> dict[str, float]:
    return {"r": rgba[0], "g": rgba[1], "b": rgba[2], "a": rgba[3]}


def _point(x: float, y: float, z: float = 0.0) -> dict[str, float]:
    return {"x": float(x), "y": float(y), "z": float(z)}


def _line(
    kind: int, points: list[dict[str, float]], thickness_m: float, rgba: Sequence[float]
) -> dict[str, Any]:
    return {
        "type": kind,
        "pose": _IDENTITY,
        "thickness": thickness_m,
        "scale_invariant": False,
        "points": points,
        "color": _color(rgba),
        "colors": [],
        "indices": [],
    }


def _entity(
    stamp: dict[str, int],
    frame_id: str,
    entity_id: str,
    *,
    frame_locked: bool,
    metadata: dict[str, str] | None = None,
    lines: list[dict[str, Any]] | None = None,
    arrows: list[dict[str, Any]] | None = None,
    texts: list[dict[str, Any]] | None = None,
) -> dict[str, Any]:
    return {
        "timestamp": stamp,
        "frame_id": frame_id,
        "id": entity_id,
        "lifetime": {"sec": 0, "nanosec": 0},
        "frame_locked": frame_locked,
        "metadata": [{"key": k, "value": v} for k, v in (metadata or {}).items()],
        "arrows": arrows or [],
        "cubes": [],
        "spheres": [],
        "cylinders": [],
        "lines": lines or [],
        "triangles": [],
        "texts": texts or [],
        "models": [],
    }


def deletion(entity_id: str, stamp: dict[str, int]) -> dict[str, Any]:
    """A SceneUpdate that removes one entity."""
    return {
        "deletions": [{"timestamp": stamp, "type": MATCHING_ID, "id": entity_id}],
        "entities": [],
    }


def zone_outline(footprint: Footprint, distance_m: float) -> list[tuple[float, float]]:
    """The footprint grown by `distance_m` (a rectangle with quarter-circle corners), in
    `base_link` counter-clockwise: what the map draws as a zone's ring."""
    front, rear, half = footprint.front_m, -footprint.rear_m, footprint.half_width_m
    corners = ((front, half, 0.0), (rear, half, 0.5), (rear, -half, 1.0), (front, -half, 1.5))
    points = []
    for x, y, start in corners:
        for step in range(CORNER_STEPS + 1):
            angle = math.pi * (start + 0.5 * step / CORNER_STEPS)
            points.append((x + distance_m * math.cos(angle), y + distance_m * math.sin(angle)))
    return points


def zones_update(
    footprint: Footprint, settings: ZoneSettings, state: ZoneState, stamp: dict[str, int]
) -> dict[str, Any]:
    """/scene/zones: one ring per zone (stop zone first), faint while the zones are off."""
    distances = (settings.stop_m, *settings.within_m)
    decision = state.decision
    limiting = None
    if state.limiting and decision is not None and decision.zone is not None:
        limiting = decision.zone + 1  # -1 the stop zone: ring 0
    lines = []
    for index, distance in enumerate(distances):
        rgb = ZONE_RGB[min(index, len(ZONE_RGB) - 1)]
        alpha = 0.86 if state.active else 0.27
        width = LIMITING_LINE_M if index == limiting else ZONE_LINE_M
        outline = [_point(x, y) for x, y in zone_outline(footprint, distance)]
        lines.append(_line(LINE_LOOP, outline, width, (*rgb, alpha)))
    metadata = {
        "state": state.text,
        "active": str(state.active).lower(),
        "limiting_zone": "none" if limiting is None else str(limiting),
        "distances_m": " ".join(f"{d:g}" for d in distances),
    }
    entity = _entity(stamp, BASE_FRAME, "zones", frame_locked=True, metadata=metadata, lines=lines)
    return {"deletions": [], "entities": [entity]}


def plan_update(points: np.ndarray[Any, Any], stamp: dict[str, int]) -> dict[str, Any]:
    """/scene/plan: the planned path in `odom` (deleted when no assisted mode runs)."""
    if len(points) < 2:
        return deletion("plan", stamp)
    line = _line(LINE_STRIP, [_point(x, y, 0.02) for x, y in points], PATH_LINE_M, PATH_RGBA)
    metadata = {"points": str(len(points))}
    entity = _entity(stamp, ODOM_FRAME, "plan", frame_locked=False, metadata=metadata, lines=[line])
    return {"deletions": [], "entities": [entity]}


def _pose(matrix: np.ndarray[Any, Any]) -> dict[str, Any]:
    x, y, z, w = quaternion_xyzw(matrix)
    position = matrix[:3, 3]
    return {
        "position": _point(position[0], position[1], position[2]),
        "orientation": {"x": x, "y": y, "z": z, "w": w},
    }


def _axis_matrix(tool: np.ndarray[Any, Any], axis: int) -> np.ndarray[Any, Any]:
    """The tool's frame turned so that its x axis lies along the tool's `axis` (an arrow
    points along +x)."""
    turn = np.eye(4)
    if axis == 1:  # +90° about z: x -> y
        turn[:2, :2] = [[0.0, -1.0], [1.0, 0.0]]
    elif axis == 2:  # -90° about y: x -> z
        turn[:3, :3] = [[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]
    result: np.ndarray[Any, Any] = tool @ turn
    return result


def arm_goal_update(
    goal: ArmGoal, tool: np.ndarray[Any, Any], base_frame: str, stamp: dict[str, int]
) -> dict[str, Any]:
    """/scene/arm_goal: the goal's target frame (`tool`, 4x4 in `base_frame`) as three axes
    and its label."""
    alpha = 1.0 if goal.accepted else 0.55
    arrows = [
        {
            "pose": _pose(_axis_matrix(tool, axis)),
            "shaft_length": AXIS_LENGTH_M * 0.75,
            "shaft_diameter": 0.01,
            "head_length": AXIS_LENGTH_M * 0.25,
            "head_diameter": 0.022,
            "color": _color((*AXIS_RGB[axis], alpha)),
        }
        for axis in range(3)
    ]
    label = tool.copy()
    label[2, 3] += AXIS_LENGTH_M * 1.3
    state = "moving" if goal.accepted else "preview"
    text = {
        "pose": _pose(label),
        "billboard": True,
        "font_size": 14.0,
        "scale_invariant": True,
        "color": _color((1.0, 1.0, 1.0, 1.0)),
        "text": f"{goal.label} ({state})",
    }
    metadata = {
        "label": goal.label,
        "state": state,
        "pose": goal.pose.describe(),
        "duration_s": f"{goal.duration_s:.2f}",
        **{joint: f"{angle:.6f}" for joint, angle in goal.joints.items()},
    }
    entity = _entity(
        stamp,
        base_frame,
        "arm_goal",
        frame_locked=True,
        metadata=metadata,
        arrows=arrows,
        texts=[text],
    )
    return {"deletions": [], "entities": [entity]}


def topics_of(profile: RobotProfile) -> list[str]:
    """The scene topics of a robot: a chassis's zones (with a footprint) and plan, an arm's
    goal."""
    topics = []
    if profile.drive_channels is not None:
        if profile.navigation.footprint is not None:
            topics.append(ZONES)
        topics.append(PLAN)
    if profile.arm is not None:
        topics.append(ARM_GOAL)
    return topics


class SceneSource:
    """The console model's zones, path and arm goal: each update when its content changed."""

    def __init__(self, model: SceneModel) -> None:
        self.model = model
        self._last: dict[str, object] = {}

    def changed(self, stamp: dict[str, int]) -> list[tuple[str, dict[str, Any]]]:
        """The updates whose content changed since the last call (all of them the first
        time)."""
        updates = []
        nav, arm = self.model.nav, self.model.arm
        if nav.drive is not None:
            if nav.footprint is not None:
                state: ZoneState = nav.zones
                key = (
                    state.active,
                    state.text,
                    state.limiting,
                    state.decision and state.decision.zone,
                )
                if self._new(ZONES, key):
                    updates.append(
                        (ZONES, zones_update(nav.footprint, nav.settings.zones, state, stamp))
                    )
            points = nav.planned_path()
            if self._new(PLAN, points.tobytes()):
                updates.append((PLAN, plan_update(points, stamp)))
        if arm is not None:
            goal: ArmGoal | None = arm.goal
            if self._new(ARM_GOAL, goal):
                if goal is None:
                    updates.append((ARM_GOAL, deletion("arm_goal", stamp)))
                else:
                    kin = arm.kinematics
                    tool = kin.tool_matrix(kin.vector(goal.joints))
                    updates.append((ARM_GOAL, arm_goal_update(goal, tool, kin.chain.base, stamp)))
        return updates

    def _new(self, topic: str, key: object) -> bool:
        if topic in self._last and self._last[topic] == key:
            return False
        self._last[topic] = key
        return True
