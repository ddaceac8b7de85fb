"""A console model driving the simulator's physics over a delayed link, on a hand-stepped clock."""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import numpy.typing as npt

from ocu.console.arm import ArmConsole
from ocu.console.model import ConsoleModel, Source
from ocu.kinematics.arm import ToolPose
from ocu.kinematics.collision import Contact
from ocu.profile import RobotProfile
from ocu.protocol import TelemetryPacket
from ocu.records import JointReading, TelemetryFrame
from tests.control.delayed_robot import DelayedRobot

TICK_S = 0.05  # the console's control timer
RESEND_S = 0.2  # the link repeats the command at 5 Hz


class Rig:
    """ConsoleModel + DelayedRobot; `tick()` advances both by one control period."""

    def __init__(
        self,
        profile: RobotProfile,
        tmp_path: Path,
        *,
        start: Mapping[str, float] | None = None,
        latency_s: float = 0.05,
        telemetry_hz: float = 10.0,
    ) -> None:
        assert profile.arm is not None
        self.profile = profile
        self.t = 0.0
        self.model = ConsoleModel(
            profile, clock=lambda: self.t, arm_poses_path=tmp_path / "arm_poses.toml"
        )
        assert self.model.arm is not None
        self.arm: ArmConsole = self.model.arm
        self.kinematics = self.arm.kinematics
        initial = dict(start if start is not None else profile.arm.poses["ready"])
        self.robot = DelayedRobot(
            profile, initial, latency_s=latency_s, telemetry_hz=telemetry_hz, deliver=self._deliver
        )
        self._sent_at = -math.inf
        self.messages: list[str] = []
        self.model.events.message.connect(self.messages.append)
        self.model.events.command_changed.connect(self._send)
        self.run(1.0)  # readings arrive, the delay is known

    def _deliver(self, readings: dict[str, JointReading], at: float, delay: float) -> None:
        self.model.on_telemetry(TelemetryFrame(TelemetryPacket(tick=0), readings, at, 0.0, delay))

    def _send(self) -> None:
        self._sent_at = self.t
        self.robot.send(self.model.command())

    def tick(self) -> None:
        """One control period: the robot and the link advance, then the console's tick."""
        self.t = round(self.t + TICK_S, 9)
        self.robot.run_until(self.t)
        self.model.update(self.t)
        if self.t - self._sent_at >= RESEND_S - 1e-9:
            self._send()

    def run(self, seconds: float) -> None:
        """Tick for a while."""
        for _ in range(round(seconds / TICK_S)):
            self.tick()

    def run_until_idle(self, limit_s: float = 30.0) -> float:
        """Tick until the arm commands nothing; the time it took."""
        start = self.t
        while self.arm.controller.active and self.t - start < limit_s:
            self.tick()
        assert not self.arm.controller.active, "the arm never finished"
        return self.t - start

    def truth(self) -> ToolPose:
        """Where tool0 really is (the simulator's joints)."""
        return self.kinematics.tool_pose(self.kinematics.vector(self.robot.joints))

    def truth_contact(self) -> Contact | None:
        """The real closest approach of the arm to the chassis, itself or the ground."""
        joints = self.robot.joints
        return self.kinematics.contact(self.kinematics.vector(joints), joints)

    def arm_velocities(self) -> dict[str, float]:
        """What the console commands on the arm's channels now (non-zero only)."""
        velocities = self.model.velocities()
        return {c: velocities[c] for c in self.arm.channels if c in velocities}

    def arm_sources(self) -> set[Source]:
        """Who commands the arm's channels."""
        return {self.model.channel(c).source for c in self.arm.channels}

    def position(self) -> npt.NDArray[np.float64]:
        """tool0's true position."""
        return self.truth().position
