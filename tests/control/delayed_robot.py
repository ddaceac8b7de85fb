"""The simulator's physics behind a delayed link, stepped by hand (no sockets, no clock).

Commands reach the robot `latency_s` after they are sent; the robot samples its joints every
telemetry period and each reading arrives `latency_s` later, with the round trip as its delay
(what the link measures). Deterministic and fast: the arm controller's loop can be tested
under field latencies in a fraction of a second.
"""

from __future__ import annotations

import heapq
import itertools
from collections.abc import Callable, Mapping

from ocu.profile import RobotProfile
from ocu.records import Command, JointReading
from ocu.sim.physics import RobotPhysics

Deliver = Callable[[dict[str, JointReading], float, float], None]


class DelayedRobot:
    """RobotPhysics with a one-way latency both ways and telemetry at a fixed rate."""

    def __init__(
        self,
        profile: RobotProfile,
        initial: Mapping[str, float],
        *,
        latency_s: float,
        telemetry_hz: float,
        deliver: Deliver,
    ) -> None:
        self.profile = profile
        self.physics = RobotPhysics(profile, initial, now_s=0.0)
        self.latency_s = latency_s
        self.period_s = 1.0 / telemetry_hz
        self.deliver = deliver
        self.now = 0.0
        self._queue: list[tuple[float, int, str, object]] = []
        self._order = itertools.count()
        self._next_sample = 0.0
        self.sent: list[tuple[float, Command]] = []

    def send(self, command: Command) -> None:
        """The OCU sends a command now."""
        self.sent.append((self.now, command))
        self._push(self.now + self.latency_s, "command", command)

    def _push(self, at: float, kind: str, item: object) -> None:
        heapq.heappush(self._queue, (at, next(self._order), kind, item))

    def run_until(self, until: float) -> None:
        """Advance the robot and the link to `until`."""
        while True:
            next_event = self._queue[0][0] if self._queue else float("inf")
            when = min(next_event, self._next_sample)
            if when > until:
                break
            if self._next_sample <= next_event:
                self.physics.advance(self._next_sample)
                readings = self._readings()
                self._push(self._next_sample + self.latency_s, "reading", readings)
                self._next_sample += self.period_s
                continue
            at, _, kind, item = heapq.heappop(self._queue)
            if kind == "command":
                assert isinstance(item, Command)
                self.physics.apply(item, at)
            else:
                assert isinstance(item, dict)
                self.deliver(item, at, 2.0 * self.latency_s)
        self.physics.advance(until)
        self.now = until

    def _readings(self) -> dict[str, JointReading]:
        out = {}
        for name, angle in self.physics.joints_rad.items():
            motor = self.profile.motors[name]
            out[name] = JointReading(
                name, motor.device_id, 1, 2, angle, 0.0, 0.3, 0, angle, 0.0, 0.3
            )
        return out

    @property
    def joints(self) -> dict[str, float]:
        """Ground truth now."""
        return self.physics.joints_rad
