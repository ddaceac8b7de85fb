"""Image correction of the robot's cameras: colour cast and fisheye distortion, per camera.

Colour: gray world (the average of a scene is gray, so each channel is scaled to the mean of
the three; the gains are smoothed over frames so moving content does not make them flicker)
or fixed gains from the profile. Distortion: remap maps from the camera's calibration,
computed once per frame size with cv2.fisheye or the standard model and then applied with
cv2.remap. Every stage is timed per frame. The OpenCV calls release the GIL.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, replace
from typing import Any, cast

import cv2
import numpy as np
import numpy.typing as npt

from ocu.profile import COLOUR_MODES, CameraCalibration, CameraSettings

Pixels = npt.NDArray[np.uint8]
# cv2.CV_16SC2 maps: int16 coordinate pairs and uint16 interpolation weights.
Map = npt.NDArray[Any]

MIN_GAIN = 0.25
MAX_GAIN = 4.0
# Weight of the newest frame in the smoothed gray-world gains.
GRAY_WORLD_SMOOTHING = 0.3
# Means below this (of 255) carry no colour information; gains stay at 1.
DARK_MEAN = 2.0
MAPS_PER_CAMERA = 2


@dataclass(frozen=True)
class CorrectionSettings:
    """What to correct on one camera."""

    colour: str = "off"
    fixed_gains_rgb: tuple[float, float, float] = (1.0, 1.0, 1.0)
    undistort: bool = False

    def __post_init__(self) -> None:
        if self.colour not in COLOUR_MODES:
            raise ValueError(f"colour must be one of {COLOUR_MODES}, got {self.colour!r}")
        if len(self.fixed_gains_rgb) != 3 or not all(
            math.isfinite(g) and g >= 0.0 for g in self.fixed_gains_rgb
        ):
            raise ValueError(
                f"fixed gains must be three finite values >= 0: {self.fixed_gains_rgb}"
            )


@dataclass(frozen=True)
class CorrectionTimings:
    """Milliseconds spent on each stage of one frame; None for a stage that did not run."""

    colour_ms: float | None = None
    undistort_ms: float | None = None

    @property
    def total_ms(self) -> float:
        """Both stages together."""
        return (self.colour_ms or 0.0) + (self.undistort_ms or 0.0)


def channel_means_bgr(image: Pixels) -> tuple[float, float, float]:
    """Mean of each colour channel of a BGR image."""
    blue, green, red, _ = cv2.mean(image)
    return float(blue), float(green), float(red)


def gray_world_gains_bgr(image: Pixels) -> tuple[float, float, float]:
    """Gains that make each channel's mean equal to the mean of all three."""
    means = channel_means_bgr(image)
    gray = sum(means) / 3.0
    if min(means) < DARK_MEAN:
        return (1.0, 1.0, 1.0)
    blue, green, red = (min(max(gray / m, MIN_GAIN), MAX_GAIN) for m in means)
    return blue, green, red


def gain_table(gains_bgr: tuple[float, float, float]) -> Pixels:
    """A 1x256x3 lookup table for cv2.LUT that scales each channel with saturation."""
    levels = np.arange(256, dtype=np.float32)
    columns = [np.clip(levels * gain + 0.5, 0, 255) for gain in gains_bgr]
    return np.stack(columns, axis=-1).astype(np.uint8).reshape(1, 256, 3)


def apply_gains(image: Pixels, gains_bgr: tuple[float, float, float]) -> Pixels:
    """Scale the channels of a BGR image in place (cv2.LUT writes into the same array)."""
    cv2.LUT(image, gain_table(gains_bgr), dst=image)
    return image


def camera_matrix(
    calibration: CameraCalibration, size_px: tuple[int, int]
) -> npt.NDArray[np.float64]:
    """The intrinsic matrix scaled from the calibration's resolution to size_px."""
    scale_x = size_px[0] / calibration.size_px[0]
    scale_y = size_px[1] / calibration.size_px[1]
    return np.array(
        [
            [calibration.focal_px[0] * scale_x, 0.0, calibration.centre_px[0] * scale_x],
            [0.0, calibration.focal_px[1] * scale_y, calibration.centre_px[1] * scale_y],
            [0.0, 0.0, 1.0],
        ]
    )


def undistort_maps(calibration: CameraCalibration, size_px: tuple[int, int]) -> tuple[Map, Map]:
    """Fixed-point remap maps that undistort frames of size_px (same output size)."""
    matrix = camera_matrix(calibration, size_px)
    coefficients = np.array(calibration.distortion, dtype=np.float64)
    identity = np.eye(3)
    if calibration.model == "fisheye":
        new_matrix = cv2.fisheye.estimateNewCameraMatrixForUndistortRectify(
            matrix, coefficients, size_px, identity, balance=calibration.balance
        )
        map1, map2 = cv2.fisheye.initUndistortRectifyMap(
            matrix, coefficients, identity, new_matrix, size_px, cv2.CV_16SC2
        )
    else:
        new_matrix, _ = cv2.getOptimalNewCameraMatrix(
            matrix, coefficients, size_px, calibration.balance, size_px
        )
        map1, map2 = cv2.initUndistortRectifyMap(
            matrix, coefficients, identity, new_matrix, size_px, cv2.CV_16SC2
        )
    return map1, map2


class Undistorter:
    """Remap maps of one camera, computed once per frame size and reused."""

    def __init__(self, calibration: CameraCalibration) -> None:
        self.calibration = calibration
        self._maps: dict[tuple[int, int], tuple[Map, Map]] = {}
        self.maps_computed = 0

    def maps(self, size_px: tuple[int, int]) -> tuple[Map, Map]:
        """The maps for a frame size, computed on first use."""
        maps = self._maps.get(size_px)
        if maps is None:
            if len(self._maps) >= MAPS_PER_CAMERA:
                self._maps.pop(next(iter(self._maps)))
            maps = undistort_maps(self.calibration, size_px)
            self._maps[size_px] = maps
            self.maps_computed += 1
        return maps

    def apply(self, image: Pixels) -> Pixels:
        """An undistorted copy of image, same size and channels."""
        height, width = image.shape[:2]
        map1, map2 = self.maps((width, height))
        result = cv2.remap(image, map1, map2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
        return cast(Pixels, result)


class Corrector:
    """Per-camera correction; settings may change from any thread, apply() runs on one."""

    def __init__(self, cameras: tuple[CameraSettings, ...]) -> None:
        self.cameras = cameras
        self._lock = threading.Lock()
        self._settings = [
            CorrectionSettings(
                colour=camera.colour,
                fixed_gains_rgb=camera.fixed_gains_rgb,
                undistort=camera.undistort and camera.calibration is not None,
            )
            for camera in cameras
        ]
        self._undistorters = [
            Undistorter(camera.calibration) if camera.calibration is not None else None
            for camera in cameras
        ]
        self._smoothed: list[tuple[float, float, float] | None] = [None] * len(cameras)

    def settings(self, camera: int) -> CorrectionSettings:
        """The settings of one camera."""
        with self._lock:
            return self._settings[camera]

    def can_undistort(self, camera: int) -> bool:
        """Whether the camera has a calibration to undistort with."""
        return 0 <= camera < len(self._undistorters) and self._undistorters[camera] is not None

    def set_settings(self, camera: int, settings: CorrectionSettings) -> None:
        """Replace one camera's settings; undistortion needs a calibration."""
        if settings.undistort and not self.can_undistort(camera):
            raise ValueError(f"camera {camera} has no calibration to undistort with")
        with self._lock:
            self._settings[camera] = settings
            if settings.colour != "gray_world":
                self._smoothed[camera] = None

    def update(self, camera: int, **changes: object) -> CorrectionSettings:
        """Change some settings of one camera; returns the new settings."""
        settings = replace(self.settings(camera), **changes)  # type: ignore[arg-type]
        self.set_settings(camera, settings)
        return settings

    def undistorter(self, camera: int) -> Undistorter | None:
        """The camera's map cache, or None without a calibration."""
        return self._undistorters[camera]

    def apply(
        self, camera: int, image: Pixels, *, learn: bool = True
    ) -> tuple[Pixels, CorrectionTimings]:
        """The corrected frame (the input may be changed in place) and the time per stage.

        `learn=False` uses the camera's smoothed gray-world gains without updating them.
        """
        if not 0 <= camera < len(self._settings):
            return image, CorrectionTimings()
        settings = self.settings(camera)
        colour_ms = None
        undistort_ms = None
        if settings.colour != "off":
            start = time.perf_counter()
            red, green, blue = settings.fixed_gains_rgb
            gains = (blue, green, red)
            if settings.colour == "gray_world":
                measured = gray_world_gains_bgr(image)
                if learn:
                    gains = self._smooth(camera, measured)
                else:
                    gains = self._smoothed[camera] or measured
            apply_gains(image, gains)
            colour_ms = (time.perf_counter() - start) * 1000.0
        undistorter = self._undistorters[camera]
        if settings.undistort and undistorter is not None:
            start = time.perf_counter()
            image = undistorter.apply(image)
            undistort_ms = (time.perf_counter() - start) * 1000.0
        return image, CorrectionTimings(colour_ms=colour_ms, undistort_ms=undistort_ms)

    def _smooth(self, camera: int, gains: tuple[float, float, float]) -> tuple[float, float, float]:
        previous = self._smoothed[camera]
        if previous is not None:
            weight = GRAY_WORLD_SMOOTHING
            blue, green, red = (
                old + weight * (new - old) for old, new in zip(previous, gains, strict=True)
            )
            gains = (blue, green, red)
        self._smoothed[camera] = gains
        return gains
