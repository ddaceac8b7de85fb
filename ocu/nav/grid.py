"""An occupancy grid built from range scans: log-odds per cell, numpy only.

The grid is fixed in the odometry frame (`size_m` square around its origin, `resolution_m`
cells). Each scan, placed at the pose odometry gives for it, lowers the log-odds of the
cells its beams pass through (free) and raises those they end in (occupied); a beam without
a return clears up to `free_reach_m`. Values are clamped, so a moved box is forgotten after
a few scans. Seed 001 asks for an obstacle map from a lidar; this is it.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from ocu.nav.geometry import Pose
from ocu.nav.scan import free_beams
from ocu.records import ScanFrame

DEFAULT_RESOLUTION_M = 0.05
DEFAULT_SIZE_M = 40.0
LOG_ODDS_FREE = -0.4
LOG_ODDS_HIT = 0.9
LOG_ODDS_LIMIT = 4.0
FREE_REACH_M = 4.0


class OccupancyGrid:
    """Log-odds occupancy around the odometry origin (see the module docstring)."""

    # A part of the console model (the navigator's): the GUI reaches it under the model's
    # lock (ocu.core.guard) - a core in another process sends what the view asks of it (the
    # scan count, the display image), never the whole grid (3.8 MB a pickle).
    guarded = True

    def __init__(
        self,
        resolution_m: float = DEFAULT_RESOLUTION_M,
        size_m: float = DEFAULT_SIZE_M,
        *,
        free_reach_m: float = FREE_REACH_M,
    ) -> None:
        if not (resolution_m > 0.0 and size_m > resolution_m):
            raise ValueError("need 0 < resolution_m < size_m")
        self.resolution_m = resolution_m
        self.cells = math.ceil(size_m / resolution_m)
        self.size_m = self.cells * resolution_m
        # World coordinates of the grid's lower-left corner (cell [0, 0]).
        self.origin_m = (-self.size_m / 2.0, -self.size_m / 2.0)
        self.free_reach_m = free_reach_m
        self.log_odds: npt.NDArray[np.float32] = np.zeros((self.cells, self.cells), np.float32)
        self._marks = np.zeros(self.cells * self.cells, dtype=bool)
        # The display image, brought up to date only where scans changed it.
        self._image = np.full((self.cells, self.cells), 128, dtype=np.uint8)
        self._dirty: list[int] | None = None
        levels = np.linspace(-LOG_ODDS_LIMIT, LOG_ODDS_LIMIT, 256)
        self._shades = np.asarray(255.0 / (1.0 + np.exp(levels)), dtype=np.uint8)
        self.scans = 0

    def clear(self) -> None:
        """Forget everything (odometry was reset: the old map no longer lines up)."""
        self.log_odds[:] = 0.0
        self._image[:] = 128
        self._dirty = None
        self.scans = 0

    def cell_of(
        self, x_m: npt.NDArray[np.floating], y_m: npt.NDArray[np.floating]
    ) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp], npt.NDArray[np.bool_]]:
        """(row, column, inside) of world points; row is y, column is x."""
        column = np.floor((x_m - self.origin_m[0]) / self.resolution_m).astype(np.intp)
        row = np.floor((y_m - self.origin_m[1]) / self.resolution_m).astype(np.intp)
        inside = (row >= 0) & (row < self.cells) & (column >= 0) & (column < self.cells)
        return row, column, inside

    def integrate(self, scan: ScanFrame, pose: Pose, mount_xy_m: tuple[float, float]) -> None:
        """Add one scan taken from a sensor at `mount_xy_m` on a robot at `pose`."""
        angles, lengths, hit = free_beams(scan, self.free_reach_m)
        if len(angles) == 0:
            return
        c, s = math.cos(pose.heading_rad), math.sin(pose.heading_rad)
        sx = pose.x_m + c * mount_xy_m[0] - s * mount_xy_m[1]
        sy = pose.y_m + s * mount_xy_m[0] + c * mount_xy_m[1]
        world_angles = angles + pose.heading_rad
        # Free space also between neighbouring beams (as far as the nearer of the two
        # reaches), so far cells are not left unknown between beams.
        if len(angles) > 1:
            between = (world_angles[:-1] + world_angles[1:]) / 2.0
            fine_angles = np.concatenate([world_angles, between])
            fine_lengths = np.concatenate([lengths, np.minimum(lengths[:-1], lengths[1:])])
        else:
            fine_angles, fine_lengths = world_angles, lengths
        step = self.resolution_m * 0.8
        samples = np.arange(0.0, float(lengths.max()), step, dtype=np.float32)
        # Every beam sampled up to a cell short of its end: those cells are free.
        along = samples[None, :]
        free = along < (fine_lengths[:, None] - self.resolution_m).astype(np.float32)
        fx = (sx + along * np.cos(fine_angles).astype(np.float32)[:, None])[free]
        fy = (sy + along * np.sin(fine_angles).astype(np.float32)[:, None])[free]
        row, column, inside = self.cell_of(fx, fy)
        self._touch(row[inside], column[inside])
        # Each cell once per scan, however many samples fell in it.
        marks = self._marks
        marks[:] = False
        marks[row[inside] * self.cells + column[inside]] = True
        flat = self.log_odds.reshape(-1)
        flat[marks] += LOG_ODDS_FREE
        hx = sx + lengths[hit] * np.cos(world_angles[hit])
        hy = sy + lengths[hit] * np.sin(world_angles[hit])
        row, column, inside = self.cell_of(hx, hy)
        marks[:] = False
        marks[row[inside] * self.cells + column[inside]] = True
        flat[marks] += LOG_ODDS_HIT
        self._touch(row[inside], column[inside])
        box = self._dirty
        if box is not None:
            region = self.log_odds[box[0] : box[1] + 1, box[2] : box[3] + 1]
            np.clip(region, -LOG_ODDS_LIMIT, LOG_ODDS_LIMIT, out=region)
        self.scans += 1

    def _touch(self, rows: npt.NDArray[np.intp], columns: npt.NDArray[np.intp]) -> None:
        """Grow the region the display image must redraw."""
        if len(rows) == 0:
            return
        box = [int(rows.min()), int(rows.max()), int(columns.min()), int(columns.max())]
        if self._dirty is not None:
            old = self._dirty
            box = [
                min(old[0], box[0]),
                max(old[1], box[1]),
                min(old[2], box[2]),
                max(old[3], box[3]),
            ]
        self._dirty = box

    def probabilities(self) -> npt.NDArray[np.float32]:
        """Occupancy probability of every cell (0.5: unknown)."""
        return np.asarray(1.0 / (1.0 + np.exp(-self.log_odds)), dtype=np.float32)

    def image(self) -> npt.NDArray[np.uint8]:
        """Grey levels for display: white free, black occupied, mid-grey unknown (row 0 = y
        lowest). The grid's own array, updated where scans changed it: do not modify."""
        box = self._dirty
        if box is not None:
            self._dirty = None
            region = self.log_odds[box[0] : box[1] + 1, box[2] : box[3] + 1]
            index = ((region + LOG_ODDS_LIMIT) * (255.0 / (2 * LOG_ODDS_LIMIT))).astype(np.intp)
            self._image[box[0] : box[1] + 1, box[2] : box[3] + 1] = self._shades[index]
        return self._image
