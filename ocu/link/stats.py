"""Packet counters, sliding-window rates and a telemetry loss estimate (no Qt, no sockets)."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass


class RateMeter:
    """Events per second over a sliding time window."""

    def __init__(self, window_s: float = 2.0) -> None:
        self.window_s = window_s
        self._times: deque[float] = deque()

    def add(self, now: float) -> None:
        """Record one event."""
        self._times.append(now)
        self._trim(now)

    def rate(self, now: float) -> float:
        """Events per second in the window ending now."""
        self._trim(now)
        return len(self._times) / self.window_s

    def _trim(self, now: float) -> None:
        limit = now - self.window_s
        while self._times and self._times[0] < limit:
            self._times.popleft()


class LossEstimator:
    """Estimates downlink loss from gaps in the telemetry tick counter.

    The robot sends telemetry at a fixed period, so consecutive ticks differ by one period;
    the smallest positive difference seen estimates it, and a gap of n periods means n - 1
    packets were lost. Repeated ticks are duplicates, falling ticks are reordered packets.
    Counts are kept over a sliding window so the figure follows the current link quality.
    """

    def __init__(self, window_s: float = 30.0) -> None:
        self.window_s = window_s
        self.period: int | None = None
        self.last_tick: int | None = None
        self.duplicates = 0
        self.reordered = 0
        self.lost_total = 0
        self._events: deque[tuple[float, int, int]] = deque()

    def add(self, tick: int, now: float) -> None:
        """Account for one telemetry packet with this tick."""
        last = self.last_tick
        if last is None:
            self.last_tick = tick
            self._push(now, received=1, lost=0)
            return
        delta = tick - last
        if delta == 0:
            self.duplicates += 1
            return
        if delta < 0:
            self.reordered += 1
            return
        if self.period is None or delta < self.period:
            self.period = delta
        lost = max(round(delta / self.period) - 1, 0)
        self.lost_total += lost
        self.last_tick = tick
        self._push(now, received=1, lost=lost)

    def loss(self, now: float) -> float | None:
        """Fraction of telemetry lost in the window, or None before the period is known."""
        self._trim(now)
        if self.period is None:
            return None
        received = sum(e[1] for e in self._events)
        lost = sum(e[2] for e in self._events)
        total = received + lost
        return lost / total if total else None

    def _push(self, now: float, received: int, lost: int) -> None:
        self._events.append((now, received, lost))
        self._trim(now)

    def _trim(self, now: float) -> None:
        limit = now - self.window_s
        while self._events and self._events[0][0] < limit:
            self._events.popleft()


@dataclass(frozen=True)
class LinkStats:
    """A snapshot of the link's counters and rates."""

    sent: int
    received: int
    telemetry: int
    video: int
    malformed: int
    foreign: int
    send_errors: int
    rcp_rate_hz: float
    telemetry_rate_hz: float
    video_rate_hz: float
    loss_estimate: float | None
    duplicates: int
    reordered: int
    last_valid_age_s: float | None
    send_rate_hz: float
    estop_latched: bool
