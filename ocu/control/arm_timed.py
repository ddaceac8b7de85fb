"""A synchronized arm move as one position command with a duration (no Qt).

Hardware with the capability "timed_moves" (ocu.core.hardware: a robot that takes "go to P
within T" itself, as the xArm's board does with CMD_SERVO_MOVE) runs a move of the arm
(a pose goal, a stored pose, a joint goal) as ONE command: every joint's goal and one end,
`Command.goals` and `Command.until`. The ArmController (ocu.control.arm) sends it for the
whole of the move's planned time and does not stream corrections on top: the robot
interpolates, and noisy readings are never fed back into the motion. Each channel's velocity
in that command is the move's mean speed, so the position controller's prediction integrates
the move as it integrates any velocity, and a link without timed moves would still end at
the goal (the velocity until the end).

A reading cannot confirm a joint finer than its resolution: a joint's arrival tolerance is
at least one step of its position reading (`reading_resolution`; the xArm's servo unit is
0.24°), else a goal between two steps could never be confirmed.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ocu.kinematics.chain import Vector
from ocu.kinematics.trajectory import SyncMove
from ocu.profile import RobotProfile

#: The capability (ocu.core.hardware.CAPABILITIES) that makes the arm's moves timed.
TIMED_MOVES = "timed_moves"


def reading_resolution(profile: RobotProfile, joint: str) -> float:
    """One step of a joint's position reading (rad; 0 when the profile does not say)."""
    motor = profile.motors.get(joint)
    if motor is None or motor.ticks_per_rad is None or motor.ticks_per_rad <= 0.0:
        return 0.0
    return 1.0 / motor.ticks_per_rad


def arrival_tolerances(
    profile: RobotProfile, joints: Sequence[str], tolerance_rad: float
) -> Vector:
    """Each joint's arrival tolerance: the move's, but never under its reading's step."""
    return np.array([max(tolerance_rad, reading_resolution(profile, j)) for j in joints])


def timed_command(
    path: SyncMove, started_at: float, channels: Sequence[str]
) -> tuple[Vector, dict[str, float], dict[str, float]]:
    """The one command of a timed move: each channel's mean speed, its goal and its end.

    Joints the move does not turn get no goal (their channel sends zero).
    """
    duration = max(path.duration_s, 1e-9)
    velocities: Vector = np.asarray(path.delta, dtype=float) / duration
    moving = np.abs(path.delta) > 0.0
    goals = {c: float(g) for c, g, m in zip(channels, path.goal, moving, strict=True) if m}
    until = dict.fromkeys(goals, started_at + path.duration_s)
    return velocities, goals, until
