"""The simulated UR arm: joint dynamics under URScript commands (speedj with its t watchdog,
stopj, servoj, movej), protective stops at the joint limits, and the TCP pose by forward
kinematics (used by ocu.sim.ur's controller)."""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ocu.profile.ur import UrArmProfile
from ocu.protocol.ur import (
    JOINTS,
    SafetyMode,
    ScriptCommand,
    Vector6,
)

log = logging.getLogger("ocu.sim.ur")

PRIMARY, SECONDARY, REALTIME = "primary", "secondary", "realtime"
PORT_KINDS = (PRIMARY, SECONDARY, REALTIME)
DEFAULT_PORTS = (30001, 30002, 30003)
#: A URScript line longer than this without a newline is garbage: dropped and counted.
MAX_LINE = 4096
#: A client that lets this much output pile up is too slow to be a client: dropped.
MAX_PENDING_OUT = 1 << 20
#: After a stall the loop catches up at most this much simulated time, then skips ahead.
MAX_CATCH_UP_S = 0.1
SETTLED_RAD = 1e-5


def vector6(values: Sequence[float]) -> Vector6:
    return (values[0], values[1], values[2], values[3], values[4], values[5])


# ---- kinematics for the TCP pose -------------------------------------------------------------


def forward_kinematics(profile: UrArmProfile, q: Sequence[float]) -> np.ndarray:
    """The tool flange's 4x4 pose in the base frame (UR's DH convention, docs/ur.md)."""
    pose = np.eye(4)
    for joint, theta in zip(profile.joints, q, strict=True):
        ct, st = math.cos(theta), math.sin(theta)
        ca, sa = math.cos(joint.dh_alpha_rad), math.sin(joint.dh_alpha_rad)
        pose = pose @ np.array(
            [
                [ct, -st * ca, st * sa, joint.dh_a_m * ct],
                [st, ct * ca, -ct * sa, joint.dh_a_m * st],
                [0.0, sa, ca, joint.dh_d_m],
                [0.0, 0.0, 0.0, 1.0],
            ]
        )
    return pose


def rotation_vector(rotation: np.ndarray) -> tuple[float, float, float]:
    """The axis-angle vector (rad) of a rotation matrix, as UR reports orientations."""
    cos_angle = max(-1.0, min(1.0, (float(np.trace(rotation)) - 1.0) / 2.0))
    angle = math.acos(cos_angle)
    if angle < 1e-9:
        return (0.0, 0.0, 0.0)
    if math.pi - angle < 1e-6:
        # Near 180°: the axis from the diagonal (the skew part vanishes).
        axis = np.sqrt(np.maximum((np.diag(rotation) + 1.0) / 2.0, 0.0))
        index = int(np.argmax(axis))
        for other in range(3):
            if other != index and rotation[index, other] < 0:
                axis[other] = -axis[other]
        return (float(axis[0] * angle), float(axis[1] * angle), float(axis[2] * angle))
    skew = np.array(
        [
            rotation[2, 1] - rotation[1, 2],
            rotation[0, 2] - rotation[2, 0],
            rotation[1, 0] - rotation[0, 1],
        ]
    )
    axis = skew / (2.0 * math.sin(angle))
    return (float(axis[0] * angle), float(axis[1] * angle), float(axis[2] * angle))


def tcp_pose(profile: UrArmProfile, q: Sequence[float]) -> Vector6:
    """x, y, z (m) and the rotation vector (rad) of the flange."""
    pose = forward_kinematics(profile, q)
    rx, ry, rz = rotation_vector(pose[:3, :3])
    return (float(pose[0, 3]), float(pose[1, 3]), float(pose[2, 3]), rx, ry, rz)


# ---- the arm ---------------------------------------------------------------------------------


@dataclass
class _Program:
    """The running URScript command and its deadline (monotonic s; inf: none)."""

    command: ScriptCommand
    started_s: float
    deadline_s: float
    accel: float
    stopping: bool = False


class UrArm:
    """The arm's joint dynamics and safety state; no sockets, no threads (the owner locks).

    Times (`now_s`) are controller time, the packets' `time_s`: the arm is deterministic in
    it however late the loop thread runs on a loaded machine.
    """

    def __init__(self, profile: UrArmProfile, q: Sequence[float] | None = None) -> None:
        self.profile = profile
        self.q = list(q) if q is not None else [0.0, -1.57, 1.57, -1.57, -1.57, 0.0]
        if len(self.q) != JOINTS:
            raise ValueError(f"initial q has {len(self.q)} values, expected {JOINTS}")
        self.qd = [0.0] * JOINTS
        self.qdd = [0.0] * JOINTS
        self.q_actual = list(self.q)
        self.qd_actual = [0.0] * JOINTS
        self.protective_stopped = False
        self.emergency_stopped = False
        self.program: _Program | None = None
        self.limit_joint: str | None = None

    @property
    def program_running(self) -> bool:
        """Whether a URScript command is running."""
        return self.program is not None

    @property
    def safety_mode(self) -> SafetyMode:
        """The safety mode the controller reports."""
        if self.emergency_stopped:
            return SafetyMode.ROBOT_EMERGENCY_STOP
        if self.protective_stopped:
            return SafetyMode.PROTECTIVE_STOP
        return SafetyMode.NORMAL

    def run(self, command: ScriptCommand, now_s: float) -> str | None:
        """Start a command (replacing the running one); a refusal's reason, or None."""
        if command.name != "stopj" and (self.protective_stopped or self.emergency_stopped):
            return f"{command.name} refused: {self.safety_mode.name}"
        cap = self.profile.max_acceleration_rad_s2
        if command.name == "speedj":
            if command.a <= 0:
                return "speedj refused: a must be > 0"
            # t = 0: the call returns when the speed is reached, and the program with it.
            deadline = now_s + command.t if command.t > 0 else math.inf
            self.program = _Program(command, now_s, deadline, min(command.a, cap))
        elif command.name == "stopj":
            self.program = _Program(command, now_s, math.inf, min(command.a, cap), stopping=True)
        elif command.name == "servoj":
            deadline = now_s + command.t + command.lookahead_time
            self.program = _Program(command, now_s, deadline, cap)
        elif command.name == "movej":
            if command.a <= 0 or command.v <= 0:
                return "movej refused: a and v must be > 0"
            self.program = _Program(command, now_s, math.inf, min(command.a, cap))
        else:
            return f"{command.name} is not supported"
        return None

    def unlock_protective_stop(self) -> None:
        """The operator's unlock (the dashboard's `unlock protective stop`)."""
        self.protective_stopped = False
        self.limit_joint = None

    def step(self, dt: float, now_s: float) -> None:
        """Advance the arm by one control period."""
        self.q_actual = list(self.q)  # the actual position lags the target by one period
        self.qd_actual = list(self.qd)
        wanted, accels = self._wanted_speeds(now_s)
        for i, joint in enumerate(self.profile.joints):
            target = max(-joint.max_speed_rad_s, min(joint.max_speed_rad_s, wanted[i]))
            step = accels[i] * dt
            change = max(-step, min(step, target - self.qd[i]))
            previous = self.qd[i]
            self.qd[i] = previous + change
            self.qdd[i] = change / dt
            self.q[i] += (previous + self.qd[i]) / 2.0 * dt
        self._check_limits()
        self._end_program_at_rest(now_s)

    def _wanted_speeds(self, now_s: float) -> tuple[list[float], list[float]]:
        """Each joint's wanted speed (rad/s) and the acceleration (rad/s²) to get there."""
        program = self.program
        cap = [self.profile.max_acceleration_rad_s2] * JOINTS
        zeros = [0.0] * JOINTS
        if program is None:
            return zeros, cap
        command = program.command
        shared = [program.accel] * JOINTS
        if program.stopping or now_s >= program.deadline_s - 1e-9:
            program.stopping = True
            return zeros, cap if command.name == "servoj" else shared
        if command.name == "speedj" and command.qd is not None:
            return list(command.qd), shared
        if command.name == "servoj" and command.q is not None:
            horizon = max(command.lookahead_time, 1e-3)
            return [(command.q[i] - self.q[i]) / horizon for i in range(JOINTS)], cap
        if command.name == "movej" and command.q is not None:
            errors = [command.q[i] - self.q[i] for i in range(JOINTS)]
            largest = max(abs(e) for e in errors)
            if largest < SETTLED_RAD:
                return zeros, shared
            speeds: list[float] = []
            accels: list[float] = []
            for error in errors:
                # Every joint's speed and acceleration scaled by its share of the longest
                # move, so that all arrive together; the braking speed for the distance left.
                share = abs(error) / largest
                accel = max(program.accel * share, 1e-9)
                limit = math.sqrt(2.0 * accel * abs(error))
                speeds.append(math.copysign(min(command.v * share, limit), error))
                accels.append(accel)
            return speeds, accels
        return zeros, cap

    def _check_limits(self) -> None:
        for i, joint in enumerate(self.profile.joints):
            if joint.min_rad is None or joint.max_rad is None:
                continue
            if joint.min_rad <= self.q[i] <= joint.max_rad:
                continue
            self.q[i] = max(joint.min_rad, min(joint.max_rad, self.q[i]))
            # A protective stop halts every joint at once (stop category 2 in reality).
            self.qd = [0.0] * JOINTS
            self.qdd = [0.0] * JOINTS
            self.protective_stopped = True
            self.limit_joint = joint.name
            self.program = None
            log.warning("protective stop: %s reached its limit", joint.name)
            return

    def _end_program_at_rest(self, now_s: float) -> None:
        program = self.program
        if program is None:
            return
        at_rest = all(abs(v) < 1e-9 for v in self.qd)
        command = program.command
        if program.stopping and at_rest:
            self.program = None
        elif command.name == "speedj" and command.t == 0 and command.qd is not None:
            if all(abs(self.qd[i] - command.qd[i]) < 1e-9 for i in range(JOINTS)):
                program.stopping = True
        elif (
            command.name == "movej"
            and command.q is not None
            and at_rest
            and all(abs(command.q[i] - self.q[i]) < 1e-4 for i in range(JOINTS))
        ):
            self.program = None
