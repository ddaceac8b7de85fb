"""A live client's arm topics (`/joint_goals`, `/arm/twist_cmd`, `/arm/named_pose`) as the
input mux's `live` source (docs/live.md).

The goals, the moves to stored poses and the arm's jog are what the ROS bridge's core does
for ROS (`ocu.ros.bridge.BridgeCore`: the position controller, the arm's synchronized moves
and its jog with their checks); the host hands one in (`GoalCore`: the live server sits
below the ROS package and names none of its types). Its velocities go into the console
model as `Source.LIVE` under the control core's lock, so the mux's table rules them as every
other source: the operator's input wins, Space, LINK LOST, focus loss and a silent GUI stop
them.

The server's thread steps the core every CONTROL_PERIOD_S (ocu.live.server): it hands it the
model's newest telemetry and link state, then runs one step. When the model stops the
source (its lock held) the core is halted on the server's thread at its next step (the core
calls the sink under its own lock, which the model's stop must not wait for); until then
whatever the core sends is sent as zeros.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Mapping, Sequence
from typing import Any, Protocol

from ocu.console.channels import Source
from ocu.control.commands import VelocityLimits
from ocu.records import CommandError, JointReading, LinkState, TelemetryFrame

log = logging.getLogger("ocu.live")


class VelocitySink(Protocol):
    """Where a goal core sends velocities."""

    def set_velocities(self, **velocities: float) -> None: ...


class GoalCore(Protocol):
    """What the live server needs of a goal core (ocu.ros.bridge.BridgeCore)."""

    @property
    def arm_available(self) -> bool: ...

    @property
    def commanding(self) -> bool: ...

    def attach(
        self,
        sink: VelocitySink,
        limits: VelocityLimits | None = None,
        *,
        link_state: Callable[[], LinkState] | None = None,
    ) -> None: ...

    def detach(self, *, stop: bool = True) -> None: ...

    def set_goals(self, names: Sequence[str], positions: Sequence[float]) -> dict[str, float]: ...

    def on_named_pose(self, name: str) -> dict[str, float]: ...

    def on_arm_twist(self, linear: Sequence[float], angular: Sequence[float]) -> bool: ...

    def refusal(self) -> str: ...

    def on_telemetry(
        self,
        readings: Mapping[str, JointReading],
        received_at: float,
        delay_s: float | None = None,
    ) -> None: ...

    def on_link_state(self, state: LinkState, reason: str = "") -> None: ...

    def step(self, now: float | None = None) -> list[str]: ...

    def halt(self, reason: str) -> list[str]: ...


class Core(Protocol):
    """The control core's side (ocu.core.manager.ControllerManager)."""

    @property
    def model(self) -> Any: ...

    @property
    def lock(self) -> threading.RLock: ...


class LiveGoals:
    """One goal core driving the model's `live` source (module docstring)."""

    def __init__(self, core: Core, goals: GoalCore) -> None:
        self.core = core
        self.goals = goals
        self._lock = threading.Lock()
        self._halt: str | None = None  # a stop the goal core has not heard yet
        self._frame: TelemetryFrame | None = None
        self._link_state: LinkState | None = None
        robot = core.model.robot
        goals.attach(self, core.model.limits, link_state=lambda: robot.link_state)

    def set_velocities(self, **velocities: float) -> None:
        """The goal core's command (its lock held): into the model as the `live` source."""
        with self._lock:
            halted = self._halt is not None
        model = self.core.model
        with self.core.lock:
            if halted or model.estopped:
                velocities = dict.fromkeys(velocities, 0.0)
            try:
                model.set_source_velocities(Source.LIVE, velocities)
            except (CommandError, ValueError) as err:
                log.warning("live: a goal's command refused: %s", err)

    def stop(self, reason: str) -> None:
        """Halt what the goal core moves at its next step (any thread, any lock held)."""
        with self._lock:
            self._halt = reason

    def settle(self) -> None:
        """On the server's thread: a pending halt now (before a new command is taken)."""
        with self._lock:
            reason, self._halt = self._halt, None
        if reason is not None:
            self.goals.halt(reason)

    def step(self, now: float) -> list[str]:
        """On the server's thread: a pending halt, the newest telemetry and link state, one
        step of the goal core; returns its messages."""
        self.settle()
        robot = self.core.model.robot
        state = robot.link_state
        if state is not self._link_state:
            self._link_state = state
            self.goals.on_link_state(state, robot.link_reason)
        frame = robot.frame
        if frame is not None and frame is not self._frame:
            self._frame = frame
            self.goals.on_telemetry(frame.readings, frame.received_at, frame.delay_s)
        return self.goals.step(now)

    @property
    def commanding(self) -> bool:
        """Whether a goal, a move or a jog is under way."""
        return self.goals.commanding

    def close(self) -> None:
        """Stop what the goal core moves and let go of the model."""
        self.goals.detach(stop=True)
