"""The Servosila Engineer as hardware components: over UDP, its simulator, a recording.

The Engineer's joints are its motors: every one reports velocity and effort (its current),
those with an encoder their position; each takes a velocity command (the tracks through
the drive channels) - the Engineer has no position command. Its capabilities come from the
profile (a chassis, cameras, an arm; the torch is the vendor protocol's) and from what the
link speaks: range scans, battery and IMU reports arrive only over the protocol extension.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Unpack

from ocu.core.hardware import EFFORT, POSITION, VELOCITY, HardwareComponent, JointInterfaces
from ocu.link.base import Link, LinkError
from ocu.link.live import LinkOptions, LiveLink, UdpLink, VirtualLink
from ocu.net.transport import VirtualWire
from ocu.profile import RobotProfile
from ocu.record.replay_link import ReplayLink
from ocu.sim.simulator import RobotSimulator

log = logging.getLogger("ocu.hardware")

# Reported only by a robot that speaks the protocol extension (status and scan packets).
EXTENSION_CAPABILITIES = frozenset({"range_scan", "battery", "imu"})


def engineer_joints(profile: RobotProfile) -> tuple[JointInterfaces, ...]:
    """Every motor of the profile as a joint with its interfaces."""
    return tuple(
        JointInterfaces(
            name=motor.name,
            state=(POSITION, VELOCITY, EFFORT) if motor.has_position else (VELOCITY, EFFORT),
            command=(VELOCITY,) if motor.channel is not None or motor.track is not None else (),
        )
        for motor in profile.motors.values()
    )


def engineer_capabilities(profile: RobotProfile, *, extension: bool) -> frozenset[str]:
    """What an Engineer with this profile can do; `extension`: its link speaks the extension."""
    # The torch is a button of the vendor protocol's RCP; first contact speaks that wire.
    capabilities = {"torch", "calibration"}
    if profile.drive_channels is not None:
        capabilities.add("drive")
    if profile.cameras:
        capabilities.add("cameras")
    if profile.arm is not None:
        capabilities.add("arm")
    if extension and profile.extension is not None:
        capabilities |= EXTENSION_CAPABILITIES
    return frozenset(capabilities)


def engineer_component(
    link: Link, *, plugin: str = "engineer", extension: bool | None = None
) -> HardwareComponent:
    """Any Engineer link as a component (extension: as the link asks for it unless told)."""
    profile = link.profile
    if extension is None:
        # A live link probes for the extension or not; a recording has what it recorded.
        extension = link.extension_enabled if isinstance(link, LiveLink) else True
    speaks = extension and profile.extension is not None
    return HardwareComponent(
        plugin,
        link,
        joints=engineer_joints(profile),
        capabilities=engineer_capabilities(profile, extension=speaks),
    )


def parse_target(target: str) -> tuple[str, int]:
    """ "HOST:PORT" to an address; LinkError if it is not one."""
    host, sep, port = target.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise LinkError(f"not HOST:PORT: {target!r}")
    return host, int(port)


def over_udp(
    profile: RobotProfile, target: str, **options: Unpack[LinkOptions]
) -> HardwareComponent:
    """The Engineer (or ocu-sim) at "HOST:PORT" over UDP, the extension asked for."""
    options.setdefault("extension", True)
    link = UdpLink(profile, parse_target(target), **options)
    return engineer_component(link, plugin="engineer", extension=options["extension"])


class SimulatedEngineer(HardwareComponent):
    """The Engineer's simulator in this process, over a virtual wire: no sockets, no ports."""

    def __init__(
        self, simulator: RobotSimulator, wire: VirtualWire, link: Link, *, extension: bool
    ) -> None:
        self.simulator = simulator
        self.wire = wire
        profile = link.profile
        super().__init__(
            "engineer-sim",
            link,
            joints=engineer_joints(profile),
            capabilities=engineer_capabilities(profile, extension=extension),
        )

    def start(self) -> None:
        """Start the simulator, then the link."""
        self.simulator.start()
        super().start()

    def shutdown(self) -> None:
        """The link's zeros last, then the simulator and the wire; idempotent."""
        super().shutdown()
        self.simulator.stop()
        self.wire.close()


def simulated(
    profile: RobotProfile,
    target: str = "",
    *,
    extended: bool = True,
    telemetry_hz: float | None = None,
    video_fps: float = 10.0,
    video_size: tuple[int, int] = (320, 240),
    seed: int | None = None,
    **options: Unpack[LinkOptions],
) -> HardwareComponent:
    """The simulator over a virtual wire (`target` is not used: it is in this process)."""
    if target:
        raise LinkError(f"the simulator runs in this process: no target, got {target!r}")
    wire = VirtualWire()
    simulator = RobotSimulator(
        profile,
        transport=wire.robot,
        telemetry_hz=telemetry_hz,
        video_fps=video_fps,
        video_size=video_size,
        seed=seed,
        extended=extended,
    )
    options["extension"] = extended
    link = VirtualLink(profile, wire.ocu, **options)
    return SimulatedEngineer(simulator, wire, link, extension=extended)


def recording(profile: RobotProfile, target: str) -> HardwareComponent:
    """A recording (an MCAP file at `target`) played back: read-only."""
    link = ReplayLink(Path(target), profile)
    return engineer_component(link, plugin="engineer-recording")
