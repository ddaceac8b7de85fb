"""The simulated planar range sensor: beams cast into the world from the robot's true pose.

A sensor of the kind seed 002's robot carried (a SICK LMS: 181 beams, 75 Hz) and seed 001
wishes for: by default 360 beams over the full circle, 10 sweeps a second, 0.05-8 m, with
Gaussian range noise. Nothing within range is `SCAN_NO_RETURN`; a reading below the minimum
range is `SCAN_INVALID`, as such sensors report. Sent over the protocol extension
(ocu.protocol.extended.ScanPacket); a vendor robot has none.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass

import numpy as np

from ocu.nav.geometry import Pose
from ocu.nav.world import World
from ocu.protocol.extended import SCAN_INVALID, SCAN_NO_RETURN, ScanPacket

DEFAULT_BEAMS = 360
DEFAULT_SCAN_HZ = 10.0
DEFAULT_RANGE_MIN_M = 0.05
DEFAULT_RANGE_MAX_M = 8.0
DEFAULT_NOISE_M = 0.01


@dataclass(frozen=True)
class RangeSensorConfig:
    """Beams, sweep rate, range and noise of the simulated sensor."""

    beams: int = DEFAULT_BEAMS
    scan_hz: float = DEFAULT_SCAN_HZ
    range_min_m: float = DEFAULT_RANGE_MIN_M
    range_max_m: float = DEFAULT_RANGE_MAX_M
    noise_m: float = DEFAULT_NOISE_M

    def __post_init__(self) -> None:
        if not 1 <= self.beams <= 4096:
            raise ValueError(f"beams must be in 1-4096, got {self.beams}")
        if not (math.isfinite(self.scan_hz) and self.scan_hz > 0.0):
            raise ValueError(f"scan_hz must be > 0, got {self.scan_hz!r}")
        if not 0.0 <= self.range_min_m < self.range_max_m <= 65.0:
            raise ValueError("need 0 <= range_min_m < range_max_m <= 65 m")
        if not (math.isfinite(self.noise_m) and self.noise_m >= 0.0):
            raise ValueError(f"noise_m must be >= 0, got {self.noise_m!r}")


DEFAULT_RANGE_SENSOR = RangeSensorConfig()


class RangeSensor:
    """Sweeps of one sensor mounted at `mount_xy_m` on the chassis."""

    def __init__(
        self,
        world: World,
        config: RangeSensorConfig = DEFAULT_RANGE_SENSOR,
        *,
        mount_xy_m: tuple[float, float] = (0.0, 0.0),
        seed: int | None = None,
    ) -> None:
        self.world = world
        self.config = config
        self.mount_xy_m = mount_xy_m
        self._rng = random.Random(seed)
        increment = 2.0 * math.pi / config.beams
        self.angle_min_rad = -math.pi
        self.angle_increment_rad = increment
        self._angles = np.asarray(
            self.angle_min_rad + increment * np.arange(config.beams), dtype=np.float64
        )
        self._sequence = 0

    def ranges_m(self, pose: Pose) -> np.ndarray:
        """True distances along each beam from the sensor (inf: nothing within range)."""
        c, s = math.cos(pose.heading_rad), math.sin(pose.heading_rad)
        mx, my = self.mount_xy_m
        origin = (pose.x_m + c * mx - s * my, pose.y_m + s * mx + c * my)
        return self.world.ray_cast(origin, self._angles + pose.heading_rad, self.config.range_max_m)

    def sweep(self, pose: Pose, capture_time_us: int) -> ScanPacket:
        """One scan packet at the pose (noise added, millimetres)."""
        config = self.config
        low_mm = round(config.range_min_m * 1000)
        high_mm = round(config.range_max_m * 1000)
        ranges: list[int] = []
        for true_m in self.ranges_m(pose):
            if not math.isfinite(true_m):
                ranges.append(SCAN_NO_RETURN)
                continue
            measured = true_m + (self._rng.gauss(0.0, config.noise_m) if config.noise_m else 0.0)
            mm = round(measured * 1000)
            if mm < low_mm:
                ranges.append(SCAN_INVALID)
            elif mm > high_mm:
                ranges.append(SCAN_NO_RETURN)
            else:
                ranges.append(mm)
        self._sequence = (self._sequence + 1) % 2**32
        return ScanPacket(
            sequence=self._sequence,
            capture_time_us=capture_time_us,
            angle_min_urad=round(self.angle_min_rad * 1e6),
            angle_increment_urad=round(self.angle_increment_rad * 1e6),
            range_min_mm=low_mm,
            range_max_mm=high_mm,
            ranges_mm=tuple(ranges),
        )
