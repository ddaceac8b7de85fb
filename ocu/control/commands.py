"""The velocity limits every command passes (the wire mapping is ocu.protocol.mapping)."""

from __future__ import annotations

import math

from ocu.profile import RobotProfile
from ocu.records import CommandError


class VelocityLimits:
    """Current maximum velocity per channel, never above the profile's hard maximum."""

    def __init__(self, profile: RobotProfile) -> None:
        self._profile = profile
        self._max = {name: ch.default_max for name, ch in profile.channels.items()}

    def get(self, channel: str) -> float:
        """Current maximum of a channel."""
        return self._max[channel]

    def set(self, channel: str, value: float) -> float:
        """Set a channel's maximum, clipped to [0, hard_max]; returns the value kept."""
        if channel not in self._max:
            raise CommandError(f"unknown velocity channel {channel!r}")
        if not math.isfinite(value):
            raise CommandError(f"{channel}: maximum must be finite, got {value!r}")
        kept = min(max(value, 0.0), self._profile.channels[channel].hard_max)
        self._max[channel] = kept
        return kept

    def as_dict(self) -> dict[str, float]:
        """A copy of all maxima."""
        return dict(self._max)

    def clamp(self, channel: str, value: float) -> float:
        """A velocity bounded by the channel's current maximum, sign kept."""
        limit = self._max[channel]
        return min(max(value, -limit), limit)
