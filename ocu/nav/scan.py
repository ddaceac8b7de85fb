"""Range scans as points: a ScanFrame's beams in the robot's frame (x forward, y left)."""

from __future__ import annotations

import numpy as np

from ocu.nav.geometry import Points
from ocu.records import ScanFrame


def beam_angles(scan: ScanFrame) -> Points:
    """Angle of every beam in the sensor's frame (rad)."""
    count = len(scan.ranges_m)
    return np.asarray(
        scan.angle_min_rad + scan.angle_increment_rad * np.arange(count), dtype=np.float64
    )


def scan_points(scan: ScanFrame, mount_xy_m: tuple[float, float] = (0.0, 0.0)) -> Points:
    """(N, 2) points the beams hit, in the robot's frame; beams without a return left out.

    The sensor is mounted at `mount_xy_m` on the chassis, facing forward.
    """
    ranges = np.asarray(scan.ranges_m, dtype=np.float64)
    angles = beam_angles(scan)
    hit = np.isfinite(ranges) & (ranges >= scan.range_min_m) & (ranges <= scan.range_max_m)
    r, a = ranges[hit], angles[hit]
    points = np.stack([r * np.cos(a) + mount_xy_m[0], r * np.sin(a) + mount_xy_m[1]], axis=-1)
    return np.asarray(points, dtype=np.float64)


def free_beams(scan: ScanFrame, reach_m: float) -> tuple[Points, Points, np.ndarray]:
    """(angles, lengths, hit) of every beam that measured something, for ray tracing: a beam
    without a return says the space is free up to `reach_m` (or its range_max)."""
    ranges = np.asarray(scan.ranges_m, dtype=np.float64)
    angles = beam_angles(scan)
    measured = ~np.isnan(ranges)
    hit = np.isfinite(ranges) & (ranges >= scan.range_min_m)
    lengths = np.where(hit, ranges, min(reach_m, scan.range_max_m))
    keep = measured & (hit | np.isinf(ranges))
    return angles[keep], np.asarray(lengths[keep], dtype=np.float64), hit[keep]
