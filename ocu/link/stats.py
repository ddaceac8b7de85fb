"""Packet counters, sliding-window rates, a telemetry loss estimate and the round trip's
jitter (no Qt, no sockets)."""

from __future__ import annotations

import itertools
import statistics
from collections import deque
from collections.abc import Sequence
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


# Tick steps within this factor of the shortest quarter's top form the one-period cluster.
PERIOD_CLUSTER = (0.5, 1.5)


@dataclass(frozen=True)
class TickLoss:
    """Telemetry loss from the tick counter of the packets received, in arrival order."""

    received: int
    lost: int
    duplicates: int
    reordered: int
    period_ticks: float | None

    @property
    def fraction(self) -> float | None:
        """Lost share of the packets sent, or None before the period is known."""
        total = self.received + self.lost
        return None if self.period_ticks is None or not total else self.lost / total


def tick_loss(ticks: Sequence[int]) -> TickLoss:
    """Packets that never arrived: the span of ticks in periods, less the distinct ticks seen.

    The robot sends telemetry at a fixed period. The period is the median of the tick steps
    near the shortest quarter of them, so one late packet followed by an on-time one (a short
    step) does not shrink it; counting over the whole span, not step by step, keeps such a
    pair from counting as a loss. Repeated ticks are duplicates, falling ones reordered.
    """
    distinct = sorted(set(ticks))
    duplicates = len(ticks) - len(distinct)
    reordered = 0
    newest: int | None = None
    for tick in ticks:
        if newest is not None and tick < newest:
            reordered += 1
        newest = tick if newest is None else max(newest, tick)
    steps = sorted(b - a for a, b in itertools.pairwise(distinct))
    if not steps:
        return TickLoss(len(distinct), 0, duplicates, reordered, None)
    quarter = steps[(len(steps) - 1) // 4]
    low, high = PERIOD_CLUSTER
    period = float(statistics.median(s for s in steps if low * quarter <= s <= high * quarter))
    expected = round((distinct[-1] - distinct[0]) / period) + 1
    return TickLoss(len(distinct), max(expected - len(distinct), 0), duplicates, reordered, period)


class LossEstimator:
    """Live downlink loss from the telemetry ticks of a sliding time window (see tick_loss)."""

    def __init__(self, window_s: float = 30.0) -> None:
        self.window_s = window_s
        self.duplicates = 0
        self.reordered = 0
        self._events: deque[tuple[float, int]] = deque()

    def add(self, tick: int, now: float) -> None:
        """Account for one telemetry packet with this tick."""
        self._trim(now)
        if any(t == tick for _, t in self._events):
            self.duplicates += 1
            return
        if self._events and tick < max(t for _, t in self._events):
            self.reordered += 1
        self._events.append((now, tick))

    def restart(self) -> None:
        """The robot restarted its tick counter: the old ticks say nothing of the new ones."""
        self._events.clear()

    def window(self, now: float) -> TickLoss:
        """Loss figures over the window ending now."""
        self._trim(now)
        return tick_loss([t for _, t in self._events])

    def loss(self, now: float) -> float | None:
        """Fraction of telemetry lost in the window, or None before the period is known."""
        return self.window(now).fraction

    def _trim(self, now: float) -> None:
        limit = now - self.window_s
        while self._events and self._events[0][0] < limit:
            self._events.popleft()


# The jitter looks at the packets of this many seconds...
JITTER_WINDOW_S = 10.0
# ...and says nothing with fewer than this many of them.
JITTER_MIN_SAMPLES = 3


class JitterMeter:
    """How much the link's delay varies: the standard deviation of per-packet delays in a
    sliding time window. The receiver feeds it each telemetry packet's arrival time less its
    tick (the robot's clock): the clocks' offset is the same for every packet and cancels."""

    def __init__(
        self, window_s: float = JITTER_WINDOW_S, min_samples: int = JITTER_MIN_SAMPLES
    ) -> None:
        self.window_s = window_s
        self.min_samples = min_samples
        self._samples: deque[tuple[float, float]] = deque()

    def add(self, delay_s: float, now: float) -> None:
        """One packet's delay (s), or its arrival less its send time on another clock."""
        self._samples.append((now, delay_s))
        self._trim(now)

    def reset(self) -> None:
        """Forget every delay (the link was lost, the robot's clock started over)."""
        self._samples.clear()

    def jitter(self, now: float) -> float | None:
        """The standard deviation of the window's delays (s), None with too few."""
        self._trim(now)
        if len(self._samples) < self.min_samples:
            return None
        return statistics.pstdev(delay for _, delay in self._samples)

    def _trim(self, now: float) -> None:
        limit = now - self.window_s
        while self._samples and self._samples[0][0] < limit:
            self._samples.popleft()


# The commands' loss looks at the robot's echoes of this many seconds.
UPLINK_WINDOW_S = 30.0
SEQUENCE_MODULUS = 2**32


# How far the link may reorder RCPs or their echoes (numbers; 20 s of RCPs at 50 Hz).
REORDER_SLACK = 1000


class UplinkLossEstimator:
    """The share of the OCU's sequenced RCPs that never reached the robot, from the robot's
    echo in its status packets: the newest sequence number applied and how many distinct
    ones were received (docs/protocol.md, status version 3).

    Between two echoes the OCU sent (newest - oldest sequence) RCPs, and the robot received
    (received - received before) of them; the window's first and last echoes give the share
    lost. Both counters wrap at 2**32; counters that go back or apart (a new sequence: the
    OCU or the robot restarted) start the window over.
    """

    def __init__(self, window_s: float = UPLINK_WINDOW_S) -> None:
        self.window_s = window_s
        self._echoes: deque[tuple[float, int, int]] = deque()

    def add(self, sequence: int, received: int, now: float) -> None:
        """One echo: the newest sequence number the robot applied and its count received.

        An echo a little older than the last one was reordered on its way (status packets
        jitter too): it says nothing new and is left out. Numbers far behind (the OCU's
        sequence started over) or a count that went back (the robot restarted) start the
        window over. A count a little ahead of the numbers sent is not a restart: RCPs that
        arrive late are counted when they arrive, after the echo of a newer one.
        """
        if self._echoes:
            _, last_sequence, last_received = self._echoes[-1]
            behind = (last_sequence - sequence) % SEQUENCE_MODULUS
            if 0 < behind <= REORDER_SLACK:
                return
            sent = (sequence - last_sequence) % SEQUENCE_MODULUS
            got = (received - last_received) % SEQUENCE_MODULUS
            if sent >= SEQUENCE_MODULUS // 2 or got > sent + REORDER_SLACK:
                self._echoes.clear()
        self._echoes.append((now, sequence, received))
        self._trim(now)

    def reset(self) -> None:
        """Forget every echo (the link was lost)."""
        self._echoes.clear()

    def loss(self, now: float) -> float | None:
        """Share of the RCPs sent in the window that never reached the robot; None while no
        two echoes are apart by at least one RCP."""
        self._trim(now)
        if len(self._echoes) < 2:
            return None
        _, first_sequence, first_received = self._echoes[0]
        _, last_sequence, last_received = self._echoes[-1]
        sent = (last_sequence - first_sequence) % SEQUENCE_MODULUS
        if not sent:
            return None
        got = (last_received - first_received) % SEQUENCE_MODULUS
        return max(0.0, 1.0 - got / sent)

    def _trim(self, now: float) -> None:
        limit = now - self.window_s
        # The last echo before the window stays: the base of what was sent within it.
        while len(self._echoes) > 1 and self._echoes[1][0] <= limit:
            self._echoes.popleft()
