"""The link's round-trip delay, measured online from the speed commands the robot echoes.

Every telemetry motor record carries the speed command the robot is executing (documents:
"speed command"). The OCU remembers, per motor, when each commanded value went on the wire.
A record that echoes value c, arriving at t_a, was taken while the robot ran c: after c's RCP
arrived there and before the next different command did. If c was sent at s_k and replaced
at s_k+1, the round trip (uplink + downlink) d satisfies t_a - s_k+1 < d <= t_a - s_k. One
packet gives such an interval per motor (a union of intervals when the value was sent more
than once lately); their intersection is the packet's delay interval.

Intervals from many packets are combined by voting: the estimate is the middle of the delay
range that the most recent intervals agree on, so a lost RCP (which makes the robot echo an
old value longer than the OCU expects) or a robot that echoes something else outvotes
nothing. Each packet's own delay is the estimate moved into that packet's interval: with
jitter every packet has its own delay, and a narrow interval knows it better than any
average. No Qt, no sockets; times are monotonic seconds.
"""

from __future__ import annotations

import bisect
from collections import deque
from collections.abc import Iterable, Mapping

DEFAULT_MAX_DELAY_S = 2.0
DEFAULT_HISTORY_S = 5.0
DEFAULT_WINDOW = 32
# The echo is an integer in telemetry units; the OCU computes it with the same rounding.
DEFAULT_TOLERANCE = 1
# Under a telemetry flood, estimation looks at one packet per this many seconds.
MIN_SAMPLE_PERIOD_S = 0.02

Interval = tuple[float, float]


def _intersect(a: list[Interval], b: list[Interval]) -> list[Interval]:
    """Intersection of two sorted lists of disjoint closed intervals."""
    out: list[Interval] = []
    i = j = 0
    while i < len(a) and j < len(b):
        low = max(a[i][0], b[j][0])
        high = min(a[i][1], b[j][1])
        if low <= high:
            out.append((low, high))
        if a[i][1] < b[j][1]:
            i += 1
        else:
            j += 1
    return out


def _union(intervals: Iterable[Interval]) -> list[Interval]:
    merged: list[Interval] = []
    for low, high in sorted(intervals):
        if merged and low <= merged[-1][1]:
            merged[-1] = (merged[-1][0], max(merged[-1][1], high))
        else:
            merged.append((low, high))
    return merged


def _closest(value: float, intervals: list[Interval]) -> float:
    """The point of a union of intervals nearest to value."""
    best = intervals[0][0]
    for low, high in intervals:
        candidate = min(max(value, low), high)
        if abs(candidate - value) < abs(best - value):
            best = candidate
    return best


class _Runs:
    """When each distinct value of one motor's commanded echo went on the wire."""

    def __init__(self) -> None:
        self.starts: list[float] = []
        self.values: list[int] = []

    def add(self, sent_at: float, value: int) -> None:
        if self.values and self.values[-1] == value:
            return
        self.starts.append(sent_at)
        self.values.append(value)

    def trim(self, before: float) -> None:
        # Keep the run that was current at `before`: it still explains older echoes.
        cut = bisect.bisect_right(self.starts, before) - 1
        if cut > 0:
            del self.starts[:cut]
            del self.values[:cut]

    def delay_intervals(
        self, received_at: float, echo: int, tolerance: int, max_delay_s: float
    ) -> list[Interval] | None:
        """Delays consistent with this echo (a union), [] if none, None if nothing was sent."""
        if not self.starts:
            return None
        found: list[Interval] = []
        oldest = received_at - max_delay_s
        first = max(bisect.bisect_right(self.starts, oldest) - 1, 0)
        for k in range(first, len(self.starts)):
            start = self.starts[k]
            if start > received_at:
                break
            if abs(self.values[k] - echo) > tolerance:
                continue
            end = self.starts[k + 1] if k + 1 < len(self.starts) else received_at
            # The first run known may have begun long before it was recorded.
            high = max_delay_s if k == 0 else min(received_at - start, max_delay_s)
            low = max(received_at - min(end, received_at), 0.0)
            if low <= high:
                found.append((low, high))
        return _union(found)


class DelayEstimator:
    """Round-trip delay of the link from echoed speed commands (see the module docstring)."""

    def __init__(
        self,
        *,
        max_delay_s: float = DEFAULT_MAX_DELAY_S,
        history_s: float = DEFAULT_HISTORY_S,
        window: int = DEFAULT_WINDOW,
        tolerance: int = DEFAULT_TOLERANCE,
    ) -> None:
        self.max_delay_s = max_delay_s
        self.history_s = history_s
        self.tolerance = tolerance
        self._runs: dict[int, _Runs] = {}
        self._votes: deque[list[Interval]] = deque(maxlen=window)
        self._estimate: float | None = None
        self._last_sample_at: float | None = None
        self.samples = 0
        self.inconsistent = 0

    @property
    def estimate_s(self) -> float | None:
        """The current round-trip estimate, None until an echo told something."""
        return self._estimate

    def reset(self) -> None:
        """Forget everything (a new robot, a link that was lost)."""
        self._runs.clear()
        self._votes.clear()
        self._estimate = None
        self._last_sample_at = None

    def on_sent(self, sent_at: float, echoes: Mapping[int, int]) -> None:
        """A command went on the wire; `echoes` is what each motor will report for it."""
        for device, value in echoes.items():
            runs = self._runs.get(device)
            if runs is None:
                runs = self._runs[device] = _Runs()
            runs.add(sent_at, value)
        cutoff = sent_at - self.history_s
        for runs in self._runs.values():
            runs.trim(cutoff)

    def on_telemetry(self, received_at: float, echoes: Mapping[int, int]) -> float | None:
        """The delay of this packet (s), or None while nothing is known."""
        if (
            self._last_sample_at is not None
            and received_at - self._last_sample_at < MIN_SAMPLE_PERIOD_S
        ):
            return self._estimate
        self._last_sample_at = received_at
        packet: list[Interval] = [(0.0, self.max_delay_s)]
        informative = False
        for device, echo in echoes.items():
            runs = self._runs.get(device)
            if runs is None:
                continue
            intervals = runs.delay_intervals(received_at, echo, self.tolerance, self.max_delay_s)
            if intervals is None:
                continue
            if intervals != [(0.0, self.max_delay_s)]:
                informative = True
            packet = _intersect(packet, intervals)
            if not packet:
                # An echo the OCU never sent: a lost RCP, or a robot that echoes something
                # else. The packet says nothing reliable.
                self.inconsistent += 1
                return self._estimate
        if not informative:
            return self._estimate
        self.samples += 1
        self._votes.append(packet)
        self._estimate = self._vote()
        return _closest(self._estimate, packet)

    def _vote(self) -> float:
        """The middle of the delay range covered by the most intervals (nearest the last)."""
        events: list[tuple[float, int]] = []
        for intervals in self._votes:
            for low, high in intervals:
                events.append((low, 0))  # starts sort before ends at the same point
                events.append((high, 1))
        events.sort()
        depth = best = 0
        regions: list[Interval] = []
        start = 0.0
        for point, kind in events:
            if kind == 0:
                depth += 1
                if depth > best:
                    best, regions = depth, []
                if depth == best:
                    start = point
            else:
                if depth == best:
                    regions.append((start, point))
                depth -= 1
        # A region open to the maximum only says "at least": its lower end is what is known.
        middles = [low if high >= self.max_delay_s else (low + high) / 2.0 for low, high in regions]
        previous = self._estimate
        if previous is None:
            return max(middles)  # the larger delay predicts more: the safe side
        return min(middles, key=lambda m: abs(m - previous))
