"""What a Cartesian jog holds the tool to: x, y, z and pitch, or the whole pose (no Qt).

`ArmController`'s jog (ocu.control.arm) tracks a reference that moves with the commanded
twist. Two task spaces:

- `PitchTask` (4 rows): x, y, z and the pitch of the tool's pointing axis — the Engineer's
  arm of four joints, and any arm jogged with a 4-value twist; the heading and the roll about
  the pointing axis are left to the smallest joint motion.
- `WholeTask` (6 rows): position and orientation — an arm of six joints or more jogged with a
  6-value twist (vx, vy, vz m/s, then wx, wy, wz rad/s about the jog frame's x, y, z: its roll,
  pitch and yaw). The reference is a whole pose; its orientation turns by the angular
  velocity, and the error fed back is the position error and the rotation vector from the
  tool's orientation to the reference's.

Both give, for joints q: the actual task value, its Jacobian, the weights that make lengths
comparable to angles (lengths in units of the arm's longest link), the task velocity a twist
in a frame asks for, the reference advanced by a velocity over a time step, and the error.
"""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np
import numpy.typing as npt

from ocu.kinematics.arm import ArmKinematics
from ocu.kinematics.chain import Vector
from ocu.model.tree import Matrix

Reference = npt.NDArray[np.float64]  # a task vector (PitchTask) or a 4x4 pose (WholeTask)


class TaskSpace(Protocol):
    """What a jog needs of its task space (see the module docstring)."""

    rows: int

    def actual(self, q: Vector) -> Reference: ...

    def jacobian(self, q: Vector) -> npt.NDArray[np.float64]: ...

    def weights(self) -> Vector: ...

    def wanted(self, rotation: Matrix, twist: Vector) -> Vector: ...

    def advance(self, reference: Reference, velocity: Vector, dt: float) -> Reference: ...

    def error(self, reference: Reference, actual: Reference) -> Vector: ...


def rotation_exp(omega: Vector) -> Matrix:
    """The rotation by a rotation vector (axis times angle, rad): Rodrigues' formula."""
    angle = float(np.linalg.norm(omega))
    if angle < 1e-12:
        return np.eye(3)
    k = np.asarray(omega, dtype=float) / angle
    cross = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    result: Matrix = np.eye(3) + math.sin(angle) * cross + (1 - math.cos(angle)) * cross @ cross
    return result


def rotation_log(rotation: Matrix) -> Vector:
    """The rotation vector (axis times angle, rad, angle in [0, π]) of a rotation matrix."""
    r = np.asarray(rotation, dtype=float)[:3, :3]
    cos = max(-1.0, min(1.0, (float(np.trace(r)) - 1.0) / 2.0))
    angle = math.acos(cos)
    skew = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    if angle < 1e-9:
        return skew / 2.0
    if math.pi - angle < 1e-6:
        # Half a turn: the axis from the symmetric part (its sign does not matter).
        axis = np.sqrt(np.maximum((np.diag(r) + 1.0) / 2.0, 0.0))
        i = int(np.argmax(axis))
        for j in range(3):
            if j != i:
                axis[j] = math.copysign(axis[j], r[i, j] + r[j, i])
        result: Vector = axis / np.linalg.norm(axis) * angle
        return result
    vector: Vector = skew * (angle / (2.0 * math.sin(angle)))
    return vector


class PitchTask:
    """x, y, z and the pointing axis's pitch (4 rows)."""

    rows = 4

    def __init__(self, kinematics: ArmKinematics) -> None:
        self.kinematics = kinematics

    def actual(self, q: Vector) -> Reference:
        pose = self.kinematics.tool_pose(q)
        return np.array([pose.x, pose.y, pose.z, pose.pitch])

    def jacobian(self, q: Vector) -> npt.NDArray[np.float64]:
        return self.kinematics.task_jacobian(q)

    def weights(self) -> Vector:
        return np.array([1.0 / self.kinematics.length_scale_m] * 3 + [1.0])

    def wanted(self, rotation: Matrix, twist: Vector) -> Vector:
        return np.concatenate([rotation @ twist[:3], twist[3:]])

    def advance(self, reference: Reference, velocity: Vector, dt: float) -> Reference:
        result: Reference = reference + velocity * dt
        return result

    def error(self, reference: Reference, actual: Reference) -> Vector:
        error: Vector = reference - actual
        error[3] = math.remainder(error[3], math.tau)
        return error


class WholeTask:
    """Position and orientation (6 rows); the reference is tool0's 4x4 pose."""

    rows = 6

    def __init__(self, kinematics: ArmKinematics) -> None:
        self.kinematics = kinematics

    def actual(self, q: Vector) -> Reference:
        return self.kinematics.tool_matrix(q)

    def jacobian(self, q: Vector) -> npt.NDArray[np.float64]:
        return self.kinematics.chain.jacobian(q)

    def weights(self) -> Vector:
        return np.array([1.0 / self.kinematics.length_scale_m] * 3 + [1.0] * 3)

    def wanted(self, rotation: Matrix, twist: Vector) -> Vector:
        return np.concatenate([rotation @ twist[:3], rotation @ twist[3:6]])

    def advance(self, reference: Reference, velocity: Vector, dt: float) -> Reference:
        result = np.array(reference, dtype=float)
        result[:3, 3] += velocity[:3] * dt
        # The angular velocity is in the base frame: it turns the orientation from the left.
        result[:3, :3] = rotation_exp(velocity[3:6] * dt) @ result[:3, :3]
        return result

    def error(self, reference: Reference, actual: Reference) -> Vector:
        turn = rotation_log(reference[:3, :3] @ actual[:3, :3].T)
        return np.concatenate([reference[:3, 3] - actual[:3, 3], turn])


def task_rows(twist_size: int) -> int:
    """The rows of the task space a twist of `twist_size` values jogs in."""
    return 6 if twist_size == 6 else 4


def task_for(kinematics: ArmKinematics, twist_size: int) -> TaskSpace:
    """The task space of a twist of 4 or 6 values."""
    return WholeTask(kinematics) if twist_size == 6 else PitchTask(kinematics)


def singularity_cause(kinematics: ArmKinematics, q: Vector) -> str:
    """Why the arm is near a singular pose, in words (for a jog's status)."""
    if kinematics.analytic is None:
        return "near a singular pose"
    bend = kinematics.elbow_bend(q)
    if abs(math.sin(bend)) < math.sin(math.radians(25.0)) and math.cos(bend) > 0.0:
        return "the arm is stretched out: the edge of the workspace"
    if abs(math.sin(bend)) < math.sin(math.radians(25.0)):
        return "the arm is folded onto itself"
    if kinematics.wrist_radius(q) < 0.1 * kinematics.length_scale_m:
        return "the wrist is over the waist axis"
    return "near a singular pose"
