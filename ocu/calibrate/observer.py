"""What arrives from the robot, kept for the probe and the calibration (any Link).

A `TelemetryLog` subscribes to a link and keeps each telemetry packet raw (device ID ->
motor record, the robot's tick, the arrival time), the raw datagrams (size, first bytes)
for the probe, the link's state and its latest statistics. Readers wait on it with a
deadline; nothing here sleeps.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

from ocu.protocol import MotorRecord, TelemetryPacket
from ocu.records import (
    DatagramReceived,
    LinkEvent,
    LinkState,
    LinkStateChanged,
    LinkStats,
    SafetyEvent,
    TelemetryFrame,
)

MAX_SAMPLES = 20_000
MAX_DATAGRAMS = 2_000
# Datagrams up to this size are kept whole (telemetry: its pad bytes); larger ones (video)
# only their first bytes.
KEEP_WHOLE_BYTES = 512
HEAD_BYTES = 16


@dataclass(frozen=True)
class Sample:
    """One telemetry packet: when it arrived (link clock), the robot's time, every motor."""

    received_at: float
    robot_time_s: float
    tick: int
    motors: dict[int, MotorRecord]

    def motor(self, device_id: int) -> MotorRecord | None:
        """The record of one device, None when the packet lacks it."""
        return self.motors.get(device_id)


@dataclass(frozen=True)
class Datagram:
    """A datagram from the robot as it arrived (for the probe): whole if small, else its head."""

    received_at: float
    size: int
    data: bytes
    kind: str


class TelemetryLog:
    """Telemetry samples, raw datagrams, link state and statistics of one link."""

    def __init__(self, tick_hz: float) -> None:
        self.tick_hz = tick_hz
        self._condition = threading.Condition()
        self._samples: deque[Sample] = deque(maxlen=MAX_SAMPLES)
        self._count = 0
        self.datagrams: deque[Datagram] = deque(maxlen=MAX_DATAGRAMS)
        self.datagram_count = 0
        self.state = LinkState.CONNECTING
        self.state_reason = ""
        self.stats: LinkStats | None = None
        self.safety: list[str] = []

    def __call__(self, event: LinkEvent) -> None:
        """The link listener (the link's threads)."""
        with self._condition:
            # The Engineer's link: its frames carry the vendor's packets, raw motor records.
            if isinstance(event, TelemetryFrame) and isinstance(event.packet, TelemetryPacket):
                packet = event.packet
                self._samples.append(
                    Sample(
                        received_at=event.received_at,
                        robot_time_s=packet.tick / self.tick_hz,
                        tick=packet.tick,
                        motors={record.device_id: record for record in packet.motors},
                    )
                )
                self._count += 1
            elif isinstance(event, DatagramReceived):
                size = len(event.data)
                kept = event.data if size <= KEEP_WHOLE_BYTES else event.data[:HEAD_BYTES]
                self.datagrams.append(Datagram(event.received_at, size, bytes(kept), event.kind))
                self.datagram_count += 1
            elif isinstance(event, LinkStateChanged):
                self.state, self.state_reason = event.state, event.reason
            elif isinstance(event, LinkStats):
                self.stats = event
            elif isinstance(event, SafetyEvent):
                self.safety.append(event.message)
            else:
                return
            self._condition.notify_all()

    # ---- reading (any thread) ----------------------------------------------------------------

    @property
    def count(self) -> int:
        """How many telemetry samples arrived so far."""
        with self._condition:
            return self._count

    def latest(self) -> Sample | None:
        """The newest sample."""
        with self._condition:
            return self._samples[-1] if self._samples else None

    def samples(self, since: float | None = None) -> list[Sample]:
        """Samples that arrived at or after `since` (link clock), oldest first."""
        with self._condition:
            if since is None:
                return list(self._samples)
            return [s for s in self._samples if s.received_at >= since]

    def wait(
        self, predicate: Callable[[], bool], timeout_s: float, poll: Callable[[], None]
    ) -> bool:
        """Wait until predicate() holds (checked on every event); False at the deadline.

        `poll` runs at least every 20 ms while waiting: the caller's heartbeat and safety
        checks (it may raise to end the wait).
        """
        deadline = time.monotonic() + timeout_s
        while True:
            poll()
            with self._condition:
                if predicate():
                    return True
                remaining = deadline - time.monotonic()
                if remaining <= 0.0:
                    return False
                self._condition.wait(min(remaining, 0.02))
