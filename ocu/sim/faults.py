"""Network fault injection for the simulator: loss, latency, jitter and duplication."""

from __future__ import annotations

import heapq
import itertools
import math
import random
import threading
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from enum import Enum

from ocu.net.transport import Address


class Direction(Enum):
    """Which way a datagram travels."""

    TO_ROBOT = "to_robot"
    TO_OCU = "to_ocu"


@dataclass(frozen=True)
class FaultConfig:
    """Fault settings applied to every datagram in each direction."""

    loss: float = 0.0
    latency_ms: float = 0.0
    jitter_ms: float = 0.0
    duplicate: float = 0.0

    def __post_init__(self) -> None:
        for name in ("loss", "duplicate"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0.0 <= value <= 1.0):
                raise ValueError(f"{name} must be a probability in [0, 1], got {value!r}")
        for name in ("latency_ms", "jitter_ms"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")

    @property
    def is_clean(self) -> bool:
        """Whether no fault is configured."""
        return self == FaultConfig()


class FaultInjector:
    """Seeded decisions for one direction: how many copies of a datagram and their delays."""

    def __init__(self, rng: random.Random) -> None:
        self._rng = rng

    def plan(self, config: FaultConfig) -> list[float]:
        """Delays in seconds of each copy to deliver; an empty list means the datagram is lost."""
        # Every draw happens whether or not it matters, so a seed gives the same decisions for
        # the same datagram sequence whatever the settings are.
        lost = self._rng.random() < config.loss
        duplicated = self._rng.random() < config.duplicate
        delays_s = [self._delay_s(config), self._delay_s(config)]
        if lost:
            return []
        return delays_s if duplicated else delays_s[:1]

    def _delay_s(self, config: FaultConfig) -> float:
        jitter_ms = self._rng.uniform(0.0, config.jitter_ms) if config.jitter_ms > 0 else 0.0
        return (config.latency_ms + jitter_ms) / 1000.0


def make_injectors(seed: int | None) -> dict[Direction, FaultInjector]:
    """One independent injector per direction, both derived from one seed."""
    master = random.Random(seed)
    return {
        direction: FaultInjector(random.Random(master.getrandbits(64))) for direction in Direction
    }


@dataclass(order=True)
class DelayedDatagram:
    """A datagram held back until its due time (monotonic seconds)."""

    due_s: float
    sequence: int
    direction: Direction = field(compare=False)
    data: bytes = field(compare=False)
    address: Address = field(compare=False)


class DelayLine:
    """A heap of delayed datagrams, released in due-time order (FIFO among equal times)."""

    def __init__(self) -> None:
        self._heap: list[DelayedDatagram] = []
        self._sequence = itertools.count()

    def __len__(self) -> int:
        return len(self._heap)

    def push(self, due_s: float, direction: Direction, data: bytes, address: Address) -> None:
        """Hold a datagram until due_s."""
        heapq.heappush(
            self._heap, DelayedDatagram(due_s, next(self._sequence), direction, data, address)
        )

    def next_due_s(self) -> float | None:
        """Due time of the earliest held datagram, or None when empty."""
        return self._heap[0].due_s if self._heap else None

    def pop_due(self, now_s: float) -> list[DelayedDatagram]:
        """Remove and return every datagram due at or before now_s, earliest first."""
        due: list[DelayedDatagram] = []
        while self._heap and self._heap[0].due_s <= now_s:
            due.append(heapq.heappop(self._heap))
        return due


Deliver = Callable[[Direction, bytes, Address, float], None]


class FaultLayer:
    """The simulated radio: every datagram each way is lost, delayed or doubled as configured.

    Settings and the cut change from any thread; route() and release_due() run on the
    simulator's loop thread, which owns the counters. `deliver(direction, data, address,
    now_s)` gets each datagram that gets through, when it is due.
    """

    def __init__(self, config: FaultConfig, seed: int | None, deliver: Deliver) -> None:
        self._deliver = deliver
        self._lock = threading.Lock()
        self._config = config
        self._cut = False
        self._injectors = make_injectors(seed)
        self._delay_line = DelayLine()
        self.dropped_to_robot = 0
        self.dropped_to_ocu = 0
        self.duplicated = 0

    @property
    def config(self) -> FaultConfig:
        """The settings in force."""
        with self._lock:
            return self._config

    def change(self, **changes: float) -> FaultConfig:
        """Change some settings (FaultConfig field names); returns the settings now in force."""
        with self._lock:
            self._config = replace(self._config, **changes)
            return self._config

    @property
    def cut(self) -> bool:
        """Whether every datagram is dropped."""
        with self._lock:
            return self._cut

    def set_cut(self, cut: bool) -> None:
        """Drop every datagram both ways (True) or let them through again (False)."""
        with self._lock:
            self._cut = cut

    def route(self, direction: Direction, data: bytes, address: Address, now_s: float) -> None:
        """Send one datagram through the faults: now, later, twice or never."""
        with self._lock:
            cut, config = self._cut, self._config
        delays_s = [] if cut else self._injectors[direction].plan(config)
        if not delays_s:
            self._count_drop(direction)
            return
        if len(delays_s) > 1:
            self.duplicated += 1
        for delay_s in delays_s:
            if delay_s > 0.0:
                self._delay_line.push(now_s + delay_s, direction, data, address)
            else:
                self._release(direction, data, address, now_s)

    def release_due(self, now_s: float) -> None:
        """Deliver the delayed datagrams that are due."""
        for delayed in self._delay_line.pop_due(now_s):
            self._release(delayed.direction, delayed.data, delayed.address, now_s)

    def next_due_s(self) -> float:
        """When the next delayed datagram is due (inf: none is held)."""
        due_s = self._delay_line.next_due_s()
        return math.inf if due_s is None else due_s

    def _release(self, direction: Direction, data: bytes, address: Address, now_s: float) -> None:
        # A cut also catches datagrams that were already in flight (delayed) when it began.
        if self.cut:
            self._count_drop(direction)
            return
        self._deliver(direction, data, address, now_s)

    def _count_drop(self, direction: Direction) -> None:
        if direction is Direction.TO_ROBOT:
            self.dropped_to_robot += 1
        else:
            self.dropped_to_ocu += 1
