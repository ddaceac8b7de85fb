"""The xArm 1S as hardware components: its board over a serial line, or its simulator.

Its joints are the six servos: each reports its position (and a speed derived from two
readings) and takes a velocity command, which the link turns into short moves
(ocu.link.xarm). Its capabilities: the arm (its URDF and seed 003's IK: the Arm dock, the 3D
model, stored poses), the battery, and timed moves: an arm move is one CMD_SERVO_MOVE of
all its servos with one duration (Command.goals, ocu.control.arm_timed).
"""

from __future__ import annotations

import logging
from typing import Any

from ocu.core.hardware import POSITION, VELOCITY, HardwareComponent, JointInterfaces
from ocu.link.base import Link, LinkError
from ocu.link.xarm import XarmLink
from ocu.link.xarm_wire import check_port
from ocu.profile import ProfileError, RobotProfile
from ocu.profile.xarm import XarmProfile, load_xarm_profile
from ocu.sim.xarm import XarmSimulator

log = logging.getLogger("ocu.hardware")

# "timed_moves": the board takes "go to P within T" (CMD_SERVO_MOVE), several servos at once.
XARM_CAPABILITIES = frozenset({"arm", "battery", "timed_moves"})


def xarm_joints(arm: XarmProfile) -> tuple[JointInterfaces, ...]:
    """The joints: position and velocity state; velocity command."""
    return tuple(
        JointInterfaces(name=name, state=(POSITION, VELOCITY), command=(VELOCITY,))
        for name in arm.joint_names
    )


def xarm_component(link: XarmLink, *, plugin: str = "xarm") -> HardwareComponent:
    """An xArm link as a component."""
    return HardwareComponent(
        plugin, link, joints=xarm_joints(link.arm), capabilities=XARM_CAPABILITIES
    )


def _arm_of(profile: RobotProfile, arm: XarmProfile | None) -> XarmProfile:
    if arm is not None:
        return arm
    try:
        return load_xarm_profile(profile.source or profile.name)
    except ProfileError as err:
        raise LinkError(f"profile {profile.name!r} is not an xArm's: {err}") from err


def over_serial(
    profile: RobotProfile, target: str, *, arm: XarmProfile | None = None, **options: Any
) -> HardwareComponent:
    """The xArm's board on serial device `target` (/dev/ttyUSB0, a pseudo-terminal)."""
    arm = _arm_of(profile, arm)
    check_port(target)
    return xarm_component(XarmLink(arm, target, profile=profile, **options))


class SimulatedXarm(HardwareComponent):
    """The xArm simulator in this process, on a pseudo-terminal the link opens."""

    def __init__(self, simulator: XarmSimulator, link: Link) -> None:
        self.simulator = simulator
        assert isinstance(link, XarmLink)
        super().__init__(
            "xarm-sim", link, joints=xarm_joints(link.arm), capabilities=XARM_CAPABILITIES
        )

    def shutdown(self) -> None:
        """The link's stop move last, then the simulator; idempotent."""
        super().shutdown()
        snapshot = self.simulator.snapshot()
        moving = [s for s, v in snapshot.velocities.items() if abs(v) > 1.0]
        log.info(
            "xArm simulator stopping: %d moves received, servos %s",
            snapshot.moves,
            f"moving {moving}" if moving else "settled",
        )
        self.simulator.stop()


def simulated(
    profile: RobotProfile,
    target: str = "",
    *,
    arm: XarmProfile | None = None,
    latency_ms: float = 0.0,
    **options: Any,
) -> HardwareComponent:
    """The xArm simulator, serving from now on (the link opens it when started)."""
    if target:
        raise LinkError(f"the xArm simulator runs in this process: no target, got {target!r}")
    arm = _arm_of(profile, arm)
    simulator = XarmSimulator(arm, latency_ms=latency_ms)
    path = simulator.start()
    try:
        link = XarmLink(arm, path, profile=profile, **options)
    except Exception:
        simulator.stop()
        raise
    return SimulatedXarm(simulator, link)


class ConsoleLinks:
    """What the console needs to drive an xArm: its links and their component, on serial
    device `robot`, else on the simulator started here (stopped by `close`)."""

    def __init__(self, arm: XarmProfile, profile: RobotProfile, robot: str | None) -> None:
        self.arm = arm
        self.profile = profile
        self.simulator: XarmSimulator | None = None
        if robot is None:
            self.simulator = XarmSimulator(arm)
            self.path = self.simulator.start()
            self.where = f"xArm simulator on {self.path}"
        else:
            check_port(robot)
            self.path = robot
            self.where = f"xArm {arm.name} on {robot}"

    def make_link(self) -> Link:
        """A new link to the board (the window starts it)."""
        return XarmLink(self.arm, self.path, profile=self.profile)

    def hardware_for(self, link: Link) -> HardwareComponent:
        """The link as the control core's component."""
        assert isinstance(link, XarmLink)
        return xarm_component(link)

    def close(self) -> None:
        """Stop the simulator started here, if any (after the window's link is shut down)."""
        if self.simulator is not None:
            self.simulator.stop()
