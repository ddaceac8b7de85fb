"""Whether the thread that owns the commands went silent while motion was commanded.

The link zeroes the command by itself when the GUI thread stops confirming it is alive for
longer than `gui_alive_timeout_s` with motion commanded (ocu.link.live). The console must then
agree — drop what it held, so nothing resumes when the thread runs again — and it must do so
at its next control tick, which may run before the link's safety event arrives.

What it must not do is stop what the operator did *after* the thread came back: a key pressed
just after a freeze is fresh input, and the link never zeroed anything if nothing moved during
the freeze. So the watch is told of every sign of life (each control tick, each command the
console pushes) with whether motion was commanded then, and reports a stall only when a gap
longer than the limit followed a moment that commanded motion.
"""

from __future__ import annotations


class StallWatch:
    """Reports gaps in the owner thread's activity that began with motion commanded."""

    def __init__(self, limit_s: float) -> None:
        if limit_s <= 0.0:
            raise ValueError(f"stall limit must be positive, got {limit_s!r}")
        self.limit_s = limit_s
        self._last_at: float | None = None
        self._moving = False
        self._stalled_s: float | None = None

    def alive(self, now: float, moving: bool) -> None:
        """The owner thread ran at `now`; `moving`: motion is commanded from now on."""
        last = self._last_at
        if last is not None and self._moving and now - last > self.limit_s:
            gap = now - last
            self._stalled_s = gap if self._stalled_s is None else max(self._stalled_s, gap)
        self._last_at = now
        self._moving = moving

    def take_stall(self) -> float | None:
        """The longest such gap since the last call (None: none), forgotten once taken."""
        stalled, self._stalled_s = self._stalled_s, None
        return stalled
