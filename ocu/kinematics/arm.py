"""The arm as the console steers it: tool0's x, y, z and pitch, the Jacobian of those four,
IK, the self-collision model and the workspace, from a robot model and the profile's [arm].

The task has four coordinates: tool0's position in the base frame and its pitch: the angle of
its pointing axis (the profile's arm.tool_axis: x for the Engineer, whose tool0 looks along x;
z for a UR, whose tool0 looks along z as ROS-Industrial has it) in the vertical plane through
the waist axis and the tool, from the outward horizontal, positive up (0 level and pointing
away from the robot, -90° straight down, beyond ±90° tilted back toward the robot; for the
Engineer ROS's pitch about y is its negative). Pitch rate is the
rotation about the horizontal axis across that plane, so the 4 x n task Jacobian is the linear
rows of the geometric Jacobian plus one row for it. Conditioning is measured with
lengths in units of the arm's reach, so that metres and radians weigh alike whatever the
robot's size.

IK is closed-form where the chain has the yaw + three-pitch structure (ocu.kinematics.analytic)
and damped least squares otherwise (ocu.kinematics.numeric), aiming the tool's pointing axis
outward at the target's azimuth and the given pitch; an arm of six joints or more keeps the
rest of the tool's orientation as it is now (the smallest turn that points it so).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ocu.kinematics.analytic import AnalyticSolution, UnreachableError, YawPitchArm
from ocu.kinematics.chain import Chain, ChainError, Vector
from ocu.kinematics.collision import CollisionModel, Contact, path_violation
from ocu.kinematics.numeric import IkError, solve
from ocu.model.mesh import MeshData
from ocu.model.tree import KinematicTree, Matrix
from ocu.model.urdf import RobotModel
from ocu.profile import TOOL_AXES, ArmSettings

FRAMES = ("base", "tool", "camera")

WORKSPACE_CELL_M = 0.02
WORKSPACE_SAMPLES = (48, 48, 16)
# Green: the ghost is light blue, stale joints amber, implausible ones red.
WORKSPACE_RGBA = (120, 220, 120, 255)


class ArmError(ValueError):
    """A pose or a move the arm cannot make; the message says why."""


@dataclass(frozen=True)
class ToolPose:
    """tool0 in the base frame: position (m) and pitch (rad, positive up)."""

    x: float
    y: float
    z: float
    pitch: float

    @property
    def position(self) -> Vector:
        """(x, y, z) as an array."""
        return np.array([self.x, self.y, self.z])

    def describe(self) -> str:
        """'x 512 y -3 z 280 mm, pitch -12.0°'."""

        def number(value: float, decimals: int) -> str:
            text = f"{value:.{decimals}f}"
            return text[1:] if text.startswith("-") and float(text) == 0.0 else text

        return (
            f"x {number(self.x * 1000, 0)} y {number(self.y * 1000, 0)} "
            f"z {number(self.z * 1000, 0)} mm, pitch {number(math.degrees(self.pitch), 1)}°"
        )


@dataclass(frozen=True)
class PathHit:
    """Where a path breaks the clearance: the index of its pose, the pair there, and that
    pair at the start when it was already too close (it came closer still)."""

    index: int
    contact: Contact
    start: Contact | None = None

    def describe(self, count: int) -> str:
        """'the path comes too close at 45% of the way: right_jaw and right_track overlap by
        12 mm' (of a path sampled at `count` poses)."""
        where = (
            "the goal" if self.index == count - 1 else f"{self.index / (count - 1):.0%} of the way"
        )
        text = f"the path comes too close at {where}: {self.contact.describe()}"
        if self.start is not None:
            text += f" (at the start {self.start.describe()}: a move may only part them)"
        return text


def outward(pose: Matrix, axis_xy: Vector, column: int = 0) -> Vector:
    """The horizontal unit vector from the yaw axis toward the frame's origin (else its
    pointing axis, the column)."""
    direction = np.array([pose[0, 3] - axis_xy[0], pose[1, 3] - axis_xy[1], 0.0])
    norm = float(np.linalg.norm(direction))
    if norm < 1e-9:
        direction = np.array([pose[0, column], pose[1, column], 0.0])
        norm = float(np.linalg.norm(direction))
        if norm < 1e-9:
            return np.array([1.0, 0.0, 0.0])
    result: Vector = direction / norm
    return result


def pitch_of(pose: Matrix, axis_xy: Vector, column: int = 0) -> float:
    """The frame's pitch (rad): its pointing axis's (x: column 0, z: 2) angle from the outward
    horizontal, up positive."""
    pointing = pose[:3, column]
    return math.atan2(float(pointing[2]), float(pointing @ outward(pose, axis_xy, column)))


def pitch_axis(pose: Matrix, axis_xy: Vector, column: int = 0) -> Vector:
    """The axis about which a positive pitch rate turns the frame: minus the lateral axis."""
    result: Vector = -np.cross(np.array([0.0, 0.0, 1.0]), outward(pose, axis_xy, column))
    return result


def _turn_onto(start: Vector, goal: Vector) -> Matrix:
    """The smallest rotation (3x3) taking unit vector `start` onto unit vector `goal`."""
    cross = np.cross(start, goal)
    sine, cosine = float(np.linalg.norm(cross)), float(start @ goal)
    if sine < 1e-12:
        if cosine > 0.0:
            return np.eye(3)
        # Opposite: half a turn about any axis across them.
        across = np.cross(start, [1.0, 0.0, 0.0])
        if np.linalg.norm(across) < 1e-6:
            across = np.cross(start, [0.0, 1.0, 0.0])
        axis = across / np.linalg.norm(across)
        return np.asarray(2.0 * np.outer(axis, axis) - np.eye(3), dtype=float)
    axis = cross / sine
    angle = math.atan2(sine, cosine)
    skew = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.asarray(
        np.eye(3) + math.sin(angle) * skew + (1.0 - math.cos(angle)) * skew @ skew, dtype=float
    )


def _path(tree: KinematicTree, link: str) -> set[str]:
    """Names of the joints above a link."""
    names = set()
    while (joint := tree.parent_joint(link)) is not None:
        names.add(joint.name)
        link = joint.parent
    return names


class ArmKinematics:
    """The arm of one robot: see the module docstring."""

    def __init__(self, model: RobotModel, settings: ArmSettings) -> None:
        self.settings = settings
        if settings.tool_axis not in TOOL_AXES:
            raise ArmError(
                f"arm.tool_axis: one of {', '.join(TOOL_AXES)}, not {settings.tool_axis!r}"
            )
        # The tool frame's column whose pitch the task holds.
        self.pointing = 0 if settings.tool_axis == "x" else 2
        self.tree: KinematicTree = model.tree.copy()
        try:
            self.chain = Chain(
                self.tree, settings.base_link, settings.tool_link, variables=settings.joints
            )
        except ChainError as err:
            raise ArmError(f"arm: {err}") from err
        if self.chain.joints != settings.joints:
            raise ArmError(
                f"arm.joints: list them from the base to the tool: {', '.join(self.chain.joints)}"
            )
        try:
            self.analytic: YawPitchArm | None = YawPitchArm(self.chain)
        except ChainError:
            self.analytic = None
        self.camera_chain: Chain | None = None
        if settings.camera_link is not None:
            try:
                self.camera_chain = Chain(
                    self.tree,
                    settings.base_link,
                    settings.camera_link,
                    variables=[
                        j for j in settings.joints if j in _path(self.tree, settings.camera_link)
                    ],
                )
            except ChainError as err:
                raise ArmError(f"arm.camera_link: {err}") from err
        self.collision = CollisionModel(
            self.tree, model.collisions, settings.joints, ground_z_m=settings.ground_z_m
        )
        self.has_collision_model = self.collision.pair_count > 0
        # The longest link (between consecutive joints, or the last joint and the tool):
        # conditioning measures lengths in it.
        axes, tool = self.chain.axes(np.zeros(self.chain.dof))
        points = [point for point, _ in axes] + [tool[:3, 3]]
        links = [float(np.linalg.norm(b - a)) for a, b in itertools.pairwise(points)]
        self.length_scale_m = max(max(links, default=1.0), 1e-3)
        # The yaw axis (the first joint's) in the plane: pitch is measured outward from it.
        self.axis_xy = axes[0][0][:2].copy() if axes else np.zeros(2)
        self._workspace: tuple[str, MeshData] | None = None

    def hold(self, angles: Mapping[str, float]) -> None:
        """Readings of the joints on the arm that it does not command (the gripper's roll)."""
        self.chain.hold(angles)
        if self.camera_chain is not None:
            self.camera_chain.hold(angles)

    @property
    def joints(self) -> tuple[str, ...]:
        """The arm's joints, base to tool."""
        return self.chain.joints

    def vector(self, angles: Mapping[str, float]) -> Vector:
        """The arm's joint values from a name -> value map (0 for those missing)."""
        return self.chain.vector(angles)

    def mapping(self, q: Vector) -> dict[str, float]:
        """Name -> value of the arm's joints."""
        return self.chain.mapping(q)

    # ---- forward -----------------------------------------------------------------------

    def tool_matrix(self, q: Vector) -> Matrix:
        """tool0's 4x4 pose in the base frame."""
        return self.chain.forward(q)

    def pitch(self, pose: Matrix) -> float:
        """The pitch of a tool pose (4x4 in the base frame): its pointing axis's."""
        return pitch_of(pose, self.axis_xy, self.pointing)

    def tool_pose(self, q: Vector) -> ToolPose:
        """tool0's position and pitch."""
        pose = self.chain.forward(q)
        return ToolPose(float(pose[0, 3]), float(pose[1, 3]), float(pose[2, 3]), self.pitch(pose))

    def task_jacobian(self, q: Vector) -> npt.NDArray[np.float64]:
        """4 x n: d(x, y, z, pitch)/dq."""
        full = self.chain.jacobian(q)
        axis = pitch_axis(self.chain.forward(q), self.axis_xy, self.pointing)
        return np.vstack([full[:3], axis @ full[3:]])

    def condition(self, q: Vector) -> float:
        """Condition number of the task Jacobian with lengths in units of the longest link."""
        jac = self.task_jacobian(q)
        jac[:3] /= self.length_scale_m
        singular = np.linalg.svd(jac, compute_uv=False)
        smallest = float(singular[-1]) if singular.size else 0.0
        if smallest <= 1e-12:
            return math.inf
        return float(singular[0]) / smallest

    def frame_rotation(self, frame: str, q: Vector, angles: Mapping[str, float]) -> Matrix:
        """The jog frame's axes in the base frame: base, tool (tool0) or camera."""
        if frame == "base":
            return np.eye(3)
        if frame == "tool":
            return self.chain.forward(q)[:3, :3]
        if frame == "camera":
            if self.camera_chain is None:
                raise ArmError("this robot's profile names no camera link (arm.camera_link)")
            self.camera_chain.hold(angles)
            values = self.camera_chain.vector(self.mapping(q))
            return self.camera_chain.forward(values)[:3, :3]
        raise ArmError(f"unknown jog frame {frame!r}; one of {', '.join(FRAMES)}")

    def elbow_bend(self, q: Vector) -> float:
        """Angle between the forearm and the upper arm in the arm's plane (0: stretched).

        Only for the yaw + three-pitch structure (0 otherwise).
        """
        arm = self.analytic
        if arm is None:
            return 0.0
        return math.remainder(
            arm.signs[1] * float(q[2]) + arm.fore_angle - arm.upper_angle, math.tau
        )

    def wrist_radius(self, q: Vector) -> float:
        """Horizontal distance from the yaw axis to the last joint's axis (the wrist)."""
        axes, _ = self.chain.axes(q)
        point = axes[-1][0]
        return float(np.hypot(point[0] - self.axis_xy[0], point[1] - self.axis_xy[1]))

    # ---- inverse -----------------------------------------------------------------------

    def solve(
        self, target: ToolPose, *, elbow: str | None = None, current: Vector | None = None
    ) -> Vector:
        """Joint values that put tool0 at the target; ArmError with the reason when none can."""
        if self.analytic is not None:
            try:
                solution: AnalyticSolution = self.analytic.solve(
                    tuple(target.position), target.pitch, elbow=elbow, current=current
                )
            except UnreachableError as err:
                raise ArmError(str(err)) from err
            return solution.q
        azimuth = math.atan2(target.y - self.axis_xy[1], target.x - self.axis_xy[0])
        c, s = math.cos(azimuth), math.sin(azimuth)
        cp, sp = math.cos(target.pitch), math.sin(target.pitch)
        pose = np.eye(4)
        # The pointing axis outward at the pitch, y across (horizontal), the third completing
        # the frame.
        pointing = np.array([c * cp, s * cp, sp])
        y_axis = np.array([-s, c, 0.0])
        if self.pointing == 0:
            pose[:3, 0], pose[:3, 1], pose[:3, 2] = pointing, y_axis, np.cross(pointing, y_axis)
        else:
            pose[:3, 0], pose[:3, 1], pose[:3, 2] = np.cross(y_axis, pointing), y_axis, pointing
        if current is not None and self.chain.dof >= 6:
            # Six joints can keep the tool's roll and heading: turn today's orientation by the
            # least that points it at the target's direction.
            now = self.chain.forward(np.asarray(current, dtype=float))[:3, :3]
            pose[:3, :3] = _turn_onto(now[:, self.pointing], pointing) @ now
        pose[:3, 3] = target.position
        try:
            return solve(self.chain, pose, current).q
        except IkError as err:
            raise ArmError(str(err)) from err

    def solve_matrix(self, pose: Matrix, *, current: Vector | None = None) -> Vector:
        """Joint values that put tool0 at a whole pose (4x4 in the base frame: position and
        orientation), for an arm of six joints or more; ArmError when none can."""
        if self.chain.dof < 6:
            raise ArmError(
                f"a whole pose needs six joints; this arm has {self.chain.dof}: give x, y, z "
                "and pitch"
            )
        try:
            return solve(self.chain, np.asarray(pose, dtype=float), current).q
        except IkError as err:
            raise ArmError(str(err)) from err

    # ---- collisions --------------------------------------------------------------------

    def contact(self, q: Vector, others: Mapping[str, float]) -> Contact | None:
        """The closest checked pair with the arm at q and the other joints at `others`."""
        if not self.has_collision_model:
            return None
        return self.collision.closest({**others, **self.mapping(q)})

    def gaps(self, q: Vector, others: Mapping[str, float]) -> Vector:
        """Every checked pair's gap with the arm at q (empty without a collision model);
        `collision.pair_contact` names a column."""
        if not self.has_collision_model:
            return np.zeros(0)
        gaps: Vector = self.collision.gaps_along([{**others, **self.mapping(q)}])[0]
        return gaps

    def check_path(self, points: list[Vector], others: Mapping[str, float]) -> PathHit | None:
        """Where a path of the arm (its first point: where the arm is) breaks the clearance,
        with the other joints at `others`; None when it does not (see check_poses)."""
        return self.check_poses([{**others, **self.mapping(q)} for q in points])

    def check_poses(self, poses: list[Mapping[str, float]]) -> PathHit | None:
        """Where a path of whole poses (joint name -> angle; the first: where the robot is)
        breaks the clearance, else None.

        Every pair keeps the clearance, except one already closer at the start: that one may
        only move apart until it is clear (ocu.kinematics.collision.path_violation).
        """
        if not self.has_collision_model or not poses:
            return None
        gaps = self.collision.gaps_along(poses)
        found = path_violation(gaps, self.settings.clearance_m)
        if found is None:
            return None
        index, column = found
        contact = self.collision.pair_contact(column, float(gaps[index, column]))
        start = self.collision.pair_contact(column, float(gaps[0, column]))
        too_close = start.distance_m < self.settings.clearance_m
        return PathHit(index, contact, start if too_close else None)

    # ---- workspace ---------------------------------------------------------------------

    def workspace_slice(self) -> tuple[str, MeshData] | None:
        """Where tool0 reaches in the arm's plane: translucent cells, in the frame of the link
        the yaw joint turns (draw it with that link's transform); None for other arms."""
        if self.analytic is None:
            return None
        if self._workspace is None:
            self._workspace = self._build_workspace()
        return self._workspace

    def _build_workspace(self) -> tuple[str, MeshData]:
        arm = self.analytic
        assert arm is not None
        counts = WORKSPACE_SAMPLES
        grids = [
            np.linspace(self.chain.lower[i + 1], self.chain.upper[i + 1], counts[i])
            for i in range(3)
        ]
        q1, q2, q3 = np.meshgrid(*grids, indexing="ij")
        s1, s2, s3 = arm.signs
        a1 = s1 * q1
        a2 = a1 + s2 * q2
        a3 = a2 + s3 * q3
        u = arm.shoulder[0] + arm.upper_m * np.cos(a1 + arm.upper_angle)
        w = arm.shoulder[1] + arm.upper_m * np.sin(a1 + arm.upper_angle)
        u = u + arm.fore_m * np.cos(a2 + arm.fore_angle)
        w = w + arm.fore_m * np.sin(a2 + arm.fore_angle)
        tu, tw = arm.tool_offset
        u = (u + np.cos(a3) * tu - np.sin(a3) * tw).ravel()
        w = (w + np.sin(a3) * tu + np.cos(a3) * tw).ravel()
        cell = WORKSPACE_CELL_M
        keys = np.unique(np.column_stack([np.floor(u / cell), np.floor(w / cell)]), axis=0)
        # Cells in the arm's plane at yaw 0, then into the frame of the yawing link.
        yaw_link = self.tree.joint(self.chain.joints[0]).child
        zero_tree = self.tree.copy()
        zero_tree.set_positions(dict.fromkeys(zero_tree.actuated_joints, 0.0))
        inverse = np.linalg.inv(zero_tree.world_transform(yaw_link)) @ zero_tree.world_transform(
            self.settings.base_link
        )
        corners = []
        for ku, kw in keys:
            if self.settings.ground_z_m is not None:
                height = arm.origin[2] + (kw + 0.5) * cell
                if height < self.settings.ground_z_m:
                    continue
            quad = [(ku, kw), (ku + 1, kw), (ku + 1, kw + 1), (ku, kw + 1)]
            for a, b in (quad[0], quad[1], quad[2], quad[0], quad[2], quad[3]):
                point = arm.plane_point(a * cell, b * cell)
                corners.append(inverse[:3, :3] @ point + inverse[:3, 3])
        positions = np.asarray(corners, dtype=np.float32).reshape(-1, 3)
        normal = (inverse[:3, :3] @ arm.lateral).astype(np.float32)
        mesh = MeshData(
            positions=positions,
            normals=np.tile(normal, (len(positions), 1)),
            colors=np.tile(np.array(WORKSPACE_RGBA, dtype=np.uint8), (len(positions), 1)),
        )
        return yaw_link, mesh
