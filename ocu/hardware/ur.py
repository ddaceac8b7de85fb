"""A Universal Robots arm as hardware components: a controller over TCP, or its simulator.

The UR's joints are its six arm joints: each reports position, velocity and effort (the
motor current, A) and takes a velocity command (speedj). Its one capability is "arm": no
chassis, cameras, torch, range sensor, battery or IMU. The link is ocu.link.ur.UrLink.

The arm's own profile (ocu/profiles/ur/*.toml) is found from the RobotProfile's `source`
when the RobotProfile was built by ocu.profile.ur_robot; it can also be given (`arm=`).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Sequence
from typing import Any

from ocu.core.hardware import EFFORT, POSITION, VELOCITY, HardwareComponent, JointInterfaces
from ocu.link.base import Link, LinkError
from ocu.link.ur import DEFAULT_PORTS, UrLink
from ocu.profile import ProfileError, RobotProfile
from ocu.profile.ur import UrArmProfile, load_ur_profile
from ocu.sim.ur import UrSimulator

log = logging.getLogger("ocu.hardware")

UR_CAPABILITIES = frozenset({"arm"})
#: On shutdown, how long the in-process simulator is given to run the link's last stopj (the
#: wait ends as soon as it has; 1 s was too short beside two hogs and a loaded console: a hog
#: run logged "its last command speedj" before the stopj was read).
STOPJ_WAIT_S = 5.0
STOPJ_POLL_S = 0.01
#: Where the in-process simulator listens (any free ports there).
SIM_HOST = "127.0.0.1"


def ur_joints(arm: UrArmProfile) -> tuple[JointInterfaces, ...]:
    """The six joints: position, velocity and effort state; velocity command."""
    return tuple(
        JointInterfaces(name=name, state=(POSITION, VELOCITY, EFFORT), command=(VELOCITY,))
        for name in arm.joint_names
    )


def ur_component(link: UrLink, *, plugin: str = "ur") -> HardwareComponent:
    """A UR link as a component."""
    return HardwareComponent(plugin, link, joints=ur_joints(link.arm), capabilities=UR_CAPABILITIES)


def _arm_of(profile: RobotProfile, arm: UrArmProfile | None) -> UrArmProfile:
    if arm is not None:
        return arm
    try:
        return load_ur_profile(profile.source or profile.name)
    except ProfileError as err:
        raise LinkError(f"profile {profile.name!r} is not a UR arm's: {err}") from err


def parse_host(target: str) -> tuple[str, tuple[int, int, int]]:
    """ "HOST" (ports 30001-30003) or "HOST:BASE" (ports BASE+1..BASE+3); LinkError if not."""
    host, sep, base = target.rpartition(":")
    if not sep:
        host, base = target, ""
    if not host:
        raise LinkError(f"not HOST or HOST:PORT_BASE: {target!r}")
    if not base:
        return host, DEFAULT_PORTS
    if not base.isdigit() or not 0 < int(base) < 65533:
        raise LinkError(f"not HOST:PORT_BASE: {target!r}")
    start = int(base)
    return host, (start + 1, start + 2, start + 3)


def over_tcp(
    profile: RobotProfile, target: str, *, arm: UrArmProfile | None = None, **options: Any
) -> HardwareComponent:
    """The UR controller at "HOST" (or "HOST:PORT_BASE") over TCP."""
    arm = _arm_of(profile, arm)
    host, ports = parse_host(target or profile.link.address)
    options.setdefault("ports", ports)
    link = UrLink(arm, host, profile=profile, **options)
    return ur_component(link)


class SimulatedUr(HardwareComponent):
    """The UR simulator in this process on 127.0.0.1 (free ports), over real TCP."""

    def __init__(self, simulator: UrSimulator, link: Link) -> None:
        self.simulator = simulator
        self._simulator_stopped = False
        assert isinstance(link, UrLink)
        super().__init__("ur-sim", link, joints=ur_joints(link.arm), capabilities=UR_CAPABILITIES)

    def shutdown(self) -> None:
        """The link's stopj last, then the simulator once it ran it (logged); idempotent."""
        super().shutdown()
        if not self._simulator_stopped:
            self._simulator_stopped = True
            self._report_stop()
        self.simulator.stop()

    def _report_stop(self) -> None:
        """Wait (at most STOPJ_WAIT_S) for the simulator to have run the link's stopj and
        brought the arm to rest, and log what it received last: the truth of the shutdown."""
        deadline = time.monotonic() + STOPJ_WAIT_S
        idle = threading.Event()
        snapshot = self.simulator.snapshot()
        while time.monotonic() < deadline:
            # The program ends with the stop's last step; the speeds read zero a cycle later
            # (a run beside two CPU hogs logged "moving (0.000 rad/s)").
            at_rest = max(abs(v) for v in snapshot.qd) == 0.0
            if snapshot.last_command == "stopj" and snapshot.program is None and at_rest:
                break
            idle.wait(STOPJ_POLL_S)  # the simulator's thread has no event to wait on
            snapshot = self.simulator.snapshot()
        speed = max(abs(v) for v in snapshot.qd)
        log.info(
            "UR simulator stopping: its last command %s, the arm %s",
            snapshot.last_command or "none",
            "at rest" if speed == 0.0 else f"moving ({speed:.3f} rad/s)",
        )


def simulated(
    profile: RobotProfile,
    target: str = "",
    *,
    arm: UrArmProfile | None = None,
    latency_ms: float = 0.0,
    initial_q: Sequence[float] | None = None,
    **options: Any,
) -> HardwareComponent:
    """The UR simulator, listening from now on (the link connects when started)."""
    if target:
        raise LinkError(f"the UR simulator runs in this process: no target, got {target!r}")
    arm = _arm_of(profile, arm)
    simulator = UrSimulator(
        arm, host=SIM_HOST, ports=(0, 0, 0), latency_ms=latency_ms, initial_q=initial_q
    )
    simulator.start()
    ports = (simulator.ports["primary"], simulator.ports["secondary"], simulator.ports["realtime"])
    try:
        link = UrLink(arm, SIM_HOST, profile=profile, ports=ports, **options)
    except Exception:
        simulator.stop()
        raise
    return SimulatedUr(simulator, link)
