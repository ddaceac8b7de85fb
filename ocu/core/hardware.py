"""The hardware component: one robot as the control core sees it (ros2_control's model).

ros2_control's `hardware_interface::SystemInterface` exports a robot's joints as named state
interfaces ("joint1/position") and command interfaces ("joint1/velocity") and is driven by the
controller manager's cycle: `read()`, the controllers' update, `write()`. Ours is the same
in miniature, protocol-neutral, over any `Link` (ocu.link.base):

- `joints`: each joint's state and command interfaces (`JointInterfaces`);
- `capabilities`: what the robot can do beyond its joints, named from `CAPABILITIES`; the
  views build what the hardware has and nothing else;
- `read_only`: a recording - `write` and `emergency_stop` do nothing and say so;
- the cycle's calls: `read(model)` (what the link reported since the last cycle, in order:
  ocu.core.feed), `write(command)` (the command, when it changed), `emergency_stop(reason)`,
  `heartbeat()` (the commanding thread is alive), and `start()` / `shutdown()`.

Plug-ins register a factory by name in a `HardwareRegistry` (pluginlib in miniature); the
Engineer's three (over UDP, its simulator over a virtual wire, a recording) are in
ocu.hardware. docs/hardware.md says how a second robot plugs in.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from ocu.core.feed import LinkFeed
from ocu.link.base import Link
from ocu.profile import RobotProfile
from ocu.records import CameraRequest, Command

if TYPE_CHECKING:
    from ocu.console.model import ConsoleModel

log = logging.getLogger("ocu.core")

# State interfaces (ros2_control's names): the joint's angle (rad) or travel (m), its speed,
# its effort (the motor current, A).
POSITION = "position"
VELOCITY = "velocity"
EFFORT = "effort"

#: What a robot may have beyond its joints; the views ask for these by name.
CAPABILITIES: Mapping[str, str] = {
    "drive": "a chassis that drives and turns (tracks or wheels): the Map dock, drive keys",
    "cameras": "cameras streaming video: the Video dock",
    "torch": "a light the operator switches: the Torch control",
    "range_scan": "a planar range sensor: scans on the map, the safety zones",
    "battery": "battery voltage and charge reports",
    "imu": "roll, pitch and heading reports",
    "arm": "a manipulator arm with joint positions: the Arm dock, stored poses",
    "calibration": "first-contact calibration over its wire (ocu calibrate): the Calibration dock",
    "timed_moves": "joint position commands with a duration the robot runs itself "
    "(Command.goals): the arm's moves go as one such command",
}


class HardwareError(ValueError):
    """A hardware plug-in is unknown, registered twice, or describes itself wrongly."""


@dataclass(frozen=True)
class JointInterfaces:
    """One joint: its name and the interfaces it exports ("position", "velocity", "effort")."""

    name: str
    state: tuple[str, ...]
    command: tuple[str, ...]

    def state_interfaces(self) -> tuple[str, ...]:
        """ros2_control's full names: "waist/position", "waist/velocity" ..."""
        return tuple(f"{self.name}/{interface}" for interface in self.state)

    def command_interfaces(self) -> tuple[str, ...]:
        """ros2_control's full names: "waist/velocity" ..."""
        return tuple(f"{self.name}/{interface}" for interface in self.command)


class HardwareComponent:
    """One robot over one Link: its joints, capabilities, and the control cycle's calls."""

    def __init__(
        self,
        plugin: str,
        link: Link,
        *,
        joints: Sequence[JointInterfaces],
        capabilities: Iterable[str],
    ) -> None:
        capabilities = frozenset(capabilities)
        unknown = sorted(capabilities - CAPABILITIES.keys())
        if unknown:
            raise HardwareError(f"{plugin}: unknown capabilities {unknown}")
        names = [joint.name for joint in joints]
        if len(set(names)) != len(names):
            raise HardwareError(f"{plugin}: a joint is named twice in {names}")
        self.plugin = plugin
        self.link = link
        self.joints: tuple[JointInterfaces, ...] = tuple(joints)
        self.capabilities = capabilities
        # Subscribed now, before the link starts: no event is lost between start and read.
        self.feed = LinkFeed(link)
        self._lock = threading.Lock()
        self._written: Command | None = None
        self._refusal_said = False
        self._shut = False

    # ---- what it is ----------------------------------------------------------------------------

    @property
    def profile(self) -> RobotProfile:
        """The robot's profile."""
        return self.link.profile

    @property
    def description(self) -> str:
        """Where the robot is ("robot 10.0.0.2:5000", "replay run.mcap")."""
        return self.link.description

    @property
    def read_only(self) -> bool:
        """Whether the hardware takes no commands (a recording)."""
        return self.link.read_only

    def has(self, capability: str) -> bool:
        """Whether the robot has this capability (a name from CAPABILITIES)."""
        if capability not in CAPABILITIES:
            raise HardwareError(f"unknown capability {capability!r}")
        return capability in self.capabilities

    def state_interfaces(self) -> tuple[str, ...]:
        """Every joint's state interfaces, by full name."""
        return tuple(name for joint in self.joints for name in joint.state_interfaces())

    def command_interfaces(self) -> tuple[str, ...]:
        """Every joint's command interfaces, by full name."""
        return tuple(name for joint in self.joints for name in joint.command_interfaces())

    # ---- life ----------------------------------------------------------------------------------

    def start(self) -> None:
        """Start talking to the robot."""
        self.link.start()

    def shutdown(self) -> None:
        """Stop: the link sends zeros last where there is a robot; idempotent."""
        with self._lock:
            shut, self._shut = self._shut, True
        if not shut:
            self.link.shutdown()
        self.feed.close()

    # ---- the cycle -----------------------------------------------------------------------------

    def read(self, model: ConsoleModel) -> None:
        """What the robot reported since the last call, into `model` (its lock held)."""
        self.feed.read(model)

    def write(self, command: Command) -> bool:
        """Command the robot, at once when the command changed; False: read-only, refused.

        The same command twice is written once: the link's own safety zeroing (its watchdog,
        LINK LOST, its e-stop) stands until the model's command changes, never undone by a
        cycle writing an unchanged command again.
        """
        if self._refuse("commands"):
            return False
        with self._lock:
            if command == self._written:
                return True
            self._written = command
            self.link.set_command(command)
        return True

    def emergency_stop(self, reason: str = "operator") -> bool:
        """Zero all motion at once, with repeats against loss; False: read-only, nothing to stop."""
        if self._refuse("the emergency stop"):
            return False
        with self._lock:
            self._written = self.link.command.stopped()
        self.link.emergency_stop(reason)
        return True

    def heartbeat(self) -> None:
        """The commanding thread is alive (the link zeroes motion when it stops hearing it)."""
        self.link.heartbeat()

    def set_stream_request(self, cameras: Sequence[CameraRequest]) -> bool:
        """Ask for these camera streams; False: the hardware has no cameras, or is read-only."""
        if not self.has("cameras") or self._refuse("stream requests"):
            return False
        self.link.set_stream_request(cameras)
        return True

    def _refuse(self, what: str) -> bool:
        if not self.read_only:
            return False
        if not self._refusal_said:
            self._refusal_said = True
            log.info("%s is read-only: %s are not sent", self.description, what)
        return True


# ---- the registry ----------------------------------------------------------------------------

# A plug-in's factory: the robot's profile, where it is (an address, a file; the plug-in says
# what), and the plug-in's own options.
HardwareFactory = Callable[..., HardwareComponent]


class HardwareRegistry:
    """Hardware plug-ins by name: pluginlib in miniature, one `register` line per plug-in."""

    def __init__(self) -> None:
        self._factories: dict[str, HardwareFactory] = {}

    def register(self, name: str, factory: HardwareFactory) -> None:
        """Make a plug-in known under `name`."""
        if name in self._factories:
            raise HardwareError(f"hardware plug-in {name!r} is registered twice")
        self._factories[name] = factory

    @property
    def names(self) -> tuple[str, ...]:
        """The registered plug-ins, in registration order."""
        return tuple(self._factories)

    def create(
        self, name: str, profile: RobotProfile, target: str = "", **options: Any
    ) -> HardwareComponent:
        """A new component of plug-in `name` (not started)."""
        factory = self._factories.get(name)
        if factory is None:
            raise HardwareError(
                f"no hardware plug-in {name!r} (known: {', '.join(self._factories)})"
            )
        return factory(profile, target, **options)
