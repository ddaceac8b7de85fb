"""What the parts of the console model (driving.py, clicktrack.py, inputs.py, video.py) use
of it.

Each part subclasses `ModelPart`, as the calibrator's steps subclass `CalibratorCore`
(ocu.calibrate.core). Here the state and the channel core stay in ConsoleModel
(ocu.console.model), which inherits every part: `ModelPart` only declares, for the type
checker, the attributes ConsoleModel sets in `__init__` and the core methods the parts call.
Nothing in it runs.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from ocu.console.arm import ArmConsole
from ocu.console.channels import ChannelCommand, ConsoleEvents, PadWish, Source
from ocu.console.robot import RobotState
from ocu.console.tracking import TrackSession
from ocu.control.commands import VelocityLimits
from ocu.control.mux import InputMux
from ocu.control.position import PositionController
from ocu.control.tracking import TrackingOptions
from ocu.nav.navigator import Navigator
from ocu.profile import RobotProfile
from ocu.records import CameraRequest


class ModelPart:
    """The console model's state and channel core as its parts see them."""

    profile: RobotProfile
    clock: Callable[[], float]
    events: ConsoleEvents
    robot: RobotState
    limits: VelocityLimits
    controller: PositionController
    mux: InputMux
    _fed_at: dict[Source, float]
    # A source's channels that end by themselves (until) and their goals (Command.goals).
    _source_ends: dict[Source, tuple[dict[str, float], dict[str, float]]]
    nav: Navigator
    arm: ArmConsole | None
    arm_error: str
    tracking_options: TrackingOptions
    _channels: dict[str, ChannelCommand]
    _drive: tuple[str, str] | None
    _drive_request: dict[str, ChannelCommand]
    _targets: dict[str, float]
    _pad: dict[str, PadWish]
    _pad_blocked: set[str]
    _held: dict[str, tuple[str, int]]
    _waypoints: tuple[tuple[float, float], ...]
    _shuttle: tuple[tuple[float, float], ...]
    _zone_text: str
    _zone_limiting: bool
    _tracking: TrackSession | None
    _camera: int | None
    _bitrate: float
    _streams: tuple[CameraRequest, ...]

    if TYPE_CHECKING:

        def hotkey_speed(self, channel: str) -> float: ...

        @property
        def held_keys(self) -> frozenset[str]: ...

        def release_estop(self) -> None: ...

        def _apply_hotkeys(self, channel: str) -> None: ...

        def _end_assist(self, reason: str) -> bool: ...

        def _end_tracking(self, reason: str, *, quiet: bool = False) -> bool: ...

        def _stop_arm(self, reason: str) -> None: ...

        def _check_channel(self, channel: str) -> None: ...

        def _operator_acted(self, *, keep_arm: bool = False) -> None: ...

        def _joint_of(self, channel: str) -> str | None: ...

        def _drop_keys(self, channel: str) -> None: ...

        def _take_manual(self, channel: str, *, keep_keys: bool = False) -> None: ...

        def _requested(self, channel: str) -> ChannelCommand: ...

        def _set_channel(self, channel: str, velocity: float, source: Source) -> None: ...

        def _store(self, channel: str, command: ChannelCommand) -> None: ...

        def _sync_targets(self) -> None: ...

        def _publish(self, now: float | None = None) -> None: ...
