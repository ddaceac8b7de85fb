"""Orbit camera around a target point, z up: the view state the mouse and the presets change.

Plain numpy, no Qt and no GL, so mouse handling is tested without a window.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ocu.model.tree import Matrix

ORBIT_DEG_PER_PX = 0.4
ZOOM_FACTOR_PER_STEP = 0.85
MIN_ELEVATION_DEG = -89.0
MAX_ELEVATION_DEG = 90.0

# Preset views: (azimuth, elevation) in degrees. Azimuth is where the eye sits, measured from
# the robot's forward axis (+x) towards its left (+y).
VIEWS: dict[str, tuple[float, float]] = {
    "front": (0.0, 0.0),
    "side": (-90.0, 0.0),  # from the robot's right: forward points right on screen
    "top": (180.0, 90.0),  # from above: forward points up on screen
    "iso": (-50.0, 24.0),
}
# Digits, because letters are the console's hotkeys.
VIEW_KEYS = {"1": "front", "2": "side", "3": "top", "4": "iso"}


def _rotation_x(angle: float) -> Matrix:
    c, s = math.cos(angle), math.sin(angle)
    m = np.eye(4)
    m[1:3, 1:3] = [[c, -s], [s, c]]
    return m


def _rotation_z(angle: float) -> Matrix:
    c, s = math.cos(angle), math.sin(angle)
    m = np.eye(4)
    m[0:2, 0:2] = [[c, -s], [s, c]]
    return m


def _translation(offset: Sequence[float] | npt.NDArray[np.float64]) -> Matrix:
    m = np.eye(4)
    m[:3, 3] = offset
    return m


@dataclass
class OrbitCamera:
    """Where the eye is: a target, a distance and two angles; a perspective lens."""

    target: npt.NDArray[np.float64]
    distance: float
    azimuth_deg: float
    elevation_deg: float
    fov_deg: float = 35.0
    home_target: npt.NDArray[np.float64] | None = None
    home_distance: float = 2.0

    @classmethod
    def framing(cls, low: npt.ArrayLike, high: npt.ArrayLike, view: str = "iso") -> OrbitCamera:
        """A camera that shows the box low..high from a preset view."""
        camera = cls(target=np.zeros(3), distance=1.0, azimuth_deg=0.0, elevation_deg=0.0)
        camera.reframe(low, high, view)
        return camera

    def reframe(self, low: npt.ArrayLike, high: npt.ArrayLike, view: str = "iso") -> None:
        """Make the box low..high the home framing and go there, from a preset view."""
        low_arr = np.asarray(low, dtype=np.float64)
        high_arr = np.asarray(high, dtype=np.float64)
        center = (low_arr + high_arr) / 2.0
        radius = max(float(np.linalg.norm(high_arr - low_arr)) / 2.0, 0.05)
        self.home_target = center
        self.home_distance = radius / math.sin(math.radians(self.fov_deg / 2.0)) * 1.05
        self.target = center.copy()
        self.distance = self.home_distance
        self.set_view(view)

    def set_view(self, name: str) -> None:
        """Jump to a preset direction (front, side, top, iso), keeping target and distance."""
        if name not in VIEWS:
            raise ValueError(f"unknown view {name!r}; expected one of {', '.join(VIEWS)}")
        self.azimuth_deg, self.elevation_deg = VIEWS[name]

    def reset(self) -> None:
        """Back to the home framing, from the iso direction."""
        if self.home_target is not None:
            self.target = self.home_target.copy()
        self.distance = self.home_distance
        self.set_view("iso")

    def orbit(self, dx_px: float, dy_px: float) -> None:
        """Turn around the target: right-drag turns the model right, down-drag tilts it."""
        self.azimuth_deg = (self.azimuth_deg - dx_px * ORBIT_DEG_PER_PX + 180.0) % 360.0 - 180.0
        self.elevation_deg = min(
            max(self.elevation_deg + dy_px * ORBIT_DEG_PER_PX, MIN_ELEVATION_DEG),
            MAX_ELEVATION_DEG,
        )

    def pan(self, dx_px: float, dy_px: float, viewport_height_px: int) -> None:
        """Slide the target in the view plane so the point under the cursor follows it."""
        metres_per_px = (2.0 * self.distance * math.tan(math.radians(self.fov_deg) / 2.0)) / max(
            viewport_height_px, 1
        )
        rotation = self.view_matrix()[:3, :3]
        right, up = rotation[0], rotation[1]  # camera axes in world coordinates
        self.target = self.target - right * dx_px * metres_per_px + up * dy_px * metres_per_px

    def zoom(self, steps: float) -> None:
        """Move closer (positive steps) or further away."""
        self.distance = min(
            max(self.distance * ZOOM_FACTOR_PER_STEP**steps, 0.05), self.home_distance * 20.0
        )

    def view_matrix(self) -> Matrix:
        """World to camera (camera looks down -z, y up on screen)."""
        turn = _rotation_z(-math.radians(self.azimuth_deg) - math.pi / 2.0)
        tilt = _rotation_x(math.radians(self.elevation_deg) - math.pi / 2.0)
        result: Matrix = np.linalg.multi_dot(
            [_translation((0.0, 0.0, -self.distance)), tilt, turn, _translation(-self.target)]
        )
        return result

    def eye(self) -> npt.NDArray[np.float64]:
        """The eye position in world coordinates."""
        azimuth = math.radians(self.azimuth_deg)
        elevation = math.radians(self.elevation_deg)
        direction = np.array(
            [
                math.cos(elevation) * math.cos(azimuth),
                math.cos(elevation) * math.sin(azimuth),
                math.sin(elevation),
            ]
        )
        result: npt.NDArray[np.float64] = self.target + self.distance * direction
        return result

    def projection_matrix(self, aspect: float) -> Matrix:
        """Perspective projection (OpenGL clip space) for a width/height ratio."""
        near = max(self.distance * 0.02, 0.005)
        far = self.distance * 10.0 + 10.0
        f = 1.0 / math.tan(math.radians(self.fov_deg) / 2.0)
        m = np.zeros((4, 4))
        m[0, 0] = f / max(aspect, 1e-6)
        m[1, 1] = f
        m[2, 2] = (far + near) / (near - far)
        m[2, 3] = 2.0 * far * near / (near - far)
        m[3, 2] = -1.0
        return m

    def project(self, points: npt.ArrayLike, width: int, height: int) -> npt.NDArray[np.float64]:
        """Pixel coordinates (x right, y down, origin top-left) of world points (n, 3)."""
        pts = np.atleast_2d(np.asarray(points, dtype=np.float64))
        homogeneous = np.column_stack([pts, np.ones(len(pts))])
        clip = homogeneous @ (self.projection_matrix(width / height) @ self.view_matrix()).T
        ndc = clip[:, :3] / clip[:, 3:4]
        result: npt.NDArray[np.float64] = np.column_stack(
            [(ndc[:, 0] + 1.0) / 2.0 * width, (1.0 - ndc[:, 1]) / 2.0 * height]
        )
        return result

    def ray(
        self, x_px: float, y_px: float, width: int, height: int
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """The world ray (origin, unit direction) under a pixel: the inverse of `project`."""
        inverse = np.linalg.inv(self.projection_matrix(width / height) @ self.view_matrix())
        ndc_x = 2.0 * x_px / width - 1.0
        ndc_y = 1.0 - 2.0 * y_px / height
        near = inverse @ np.array([ndc_x, ndc_y, -1.0, 1.0])
        far = inverse @ np.array([ndc_x, ndc_y, 1.0, 1.0])
        start = near[:3] / near[3]
        end = far[:3] / far[3]
        direction = end - start
        result: npt.NDArray[np.float64] = direction / np.linalg.norm(direction)
        return start, result

    def pick_on_height(
        self, x_px: float, y_px: float, width: int, height: int, z_m: float
    ) -> npt.NDArray[np.float64] | None:
        """The world point under a pixel on the horizontal plane z = z_m (None: parallel, or
        behind the eye)."""
        origin, direction = self.ray(x_px, y_px, width, height)
        if abs(direction[2]) < 1e-9:
            return None
        t = (z_m - origin[2]) / direction[2]
        if t <= 0.0:
            return None
        result: npt.NDArray[np.float64] = origin + t * direction
        return result
