"""Colour-cast correction and undistortion: sizes, gains, maps once, straightened lines."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import numpy.typing as npt
import pytest

from ocu.profile import CameraCalibration, CameraSettings, RobotProfile
from ocu.video.correction import (
    CorrectionSettings,
    Corrector,
    Undistorter,
    apply_gains,
    camera_matrix,
    channel_means_bgr,
    gray_world_gains_bgr,
)

SIZE = (640, 480)
CAST_BGR = (0.8, 1.25, 0.85)  # a green cast, as the documents describe


def patches(size: tuple[int, int] = SIZE) -> npt.NDArray[np.uint8]:
    """A neutral scene: gray patches of several levels."""
    width, height = size
    image = np.zeros((height, width, 3), np.uint8)
    for k, level in enumerate((40, 90, 140, 190)):
        image[:, k * width // 4 : (k + 1) * width // 4] = level
    return image


def with_cast(image: npt.NDArray[np.uint8]) -> npt.NDArray[np.uint8]:
    scaled = np.clip(image * np.array(CAST_BGR), 0, 255)
    result: npt.NDArray[np.uint8] = scaled.astype(np.uint8)
    return result


def test_gray_world_removes_a_green_cast() -> None:
    cast = with_cast(patches())
    blue, green, red = channel_means_bgr(cast)
    assert green > 1.4 * blue
    corrected = apply_gains(cast.copy(), gray_world_gains_bgr(cast))
    blue, green, red = channel_means_bgr(corrected)
    assert max(blue, green, red) - min(blue, green, red) < 0.02 * green


def test_fixed_gains_restore_the_scene() -> None:
    scene = patches()
    blue, green, red = CAST_BGR
    gains_rgb = (1.0 / red, 1.0 / green, 1.0 / blue)
    corrector = Corrector(
        (dataclasses.replace(_camera(), colour="fixed", fixed_gains_rgb=gains_rgb),)
    )
    corrected, timings = corrector.apply(0, with_cast(scene))
    assert np.abs(corrected.astype(int) - scene.astype(int)).max() <= 2
    assert timings.colour_ms is not None
    assert timings.undistort_ms is None


def test_dark_frame_keeps_unit_gains() -> None:
    assert gray_world_gains_bgr(np.zeros((10, 10, 3), np.uint8)) == (1.0, 1.0, 1.0)


@pytest.mark.parametrize("size", [(640, 480), (320, 240), (800, 600), (1280, 720)])
def test_every_camera_keeps_size_and_channels(profile: RobotProfile, size: tuple[int, int]) -> None:
    corrector = Corrector(profile.cameras)
    for camera in range(len(profile.cameras)):
        corrector.update(camera, colour="gray_world", undistort=True)
        out, timings = corrector.apply(camera, with_cast(patches(size)))
        assert out.shape == (size[1], size[0], 3)
        assert out.dtype == np.uint8
        assert timings.colour_ms is not None
        assert timings.colour_ms >= 0.0
        assert timings.undistort_ms is not None
        assert timings.undistort_ms >= 0.0


def test_maps_are_computed_once_per_size(profile: RobotProfile) -> None:
    calibration = profile.cameras[0].calibration
    assert calibration is not None
    undistorter = Undistorter(calibration)
    first = undistorter.maps(SIZE)
    for _ in range(3):
        undistorter.apply(patches())
    assert undistorter.maps(SIZE)[0] is first[0]
    assert undistorter.maps_computed == 1
    undistorter.apply(patches((320, 240)))
    assert undistorter.maps_computed == 2


def test_undistort_needs_a_calibration(profile: RobotProfile) -> None:
    uncalibrated = dataclasses.replace(profile.cameras[0], calibration=None)
    corrector = Corrector((uncalibrated,))
    assert not corrector.can_undistort(0)
    with pytest.raises(ValueError, match="no calibration"):
        corrector.set_settings(0, CorrectionSettings(undistort=True))
    with pytest.raises(ValueError, match="colour must be one of"):
        CorrectionSettings(colour="sepia")


def _camera() -> CameraSettings:
    return CameraSettings(name="test", index=0)


# ---- a known distortion straightened --------------------------------------------------------


def _distorted_line(
    calibration: CameraCalibration, start: tuple[float, float], end: tuple[float, float]
) -> npt.NDArray[np.uint8]:
    """An image of one straight line of the ideal (pinhole) view, seen through the lens.

    The lens model here is OpenCV's own projection, independent of the code under test.
    """
    t = np.linspace(0.0, 1.0, 400)
    matrix = camera_matrix(calibration, SIZE)
    # Ends are given as fractions of the half picture, as a pinhole camera would see them.
    half_x = SIZE[0] / 2 / matrix[0, 0]
    half_y = SIZE[1] / 2 / matrix[1, 1]
    normalized = np.stack(
        [
            (start[0] + (end[0] - start[0]) * t) * half_x,
            (start[1] + (end[1] - start[1]) * t) * half_y,
        ],
        axis=-1,
    )
    coefficients = np.array(calibration.distortion)
    if calibration.model == "fisheye":
        pixels = cv2.fisheye.distortPoints(normalized.reshape(-1, 1, 2), matrix, coefficients)
    else:
        points3d = np.concatenate([normalized, np.ones((len(t), 1))], axis=1)
        pixels, _ = cv2.projectPoints(points3d, np.zeros(3), np.zeros(3), matrix, coefficients)
    image = np.zeros((SIZE[1], SIZE[0], 3), np.uint8)
    polyline = np.round(pixels.reshape(-1, 2)).astype(np.int32)
    cv2.polylines(image, [polyline], isClosed=False, color=(255, 255, 255), thickness=2)
    return image


def _deviation_px(image: npt.NDArray[np.uint8]) -> float:
    """Largest distance of the line's centre from the best straight line through it.

    The centre is taken across the line (per column of a flat line, per row of a steep one)
    so the line's width does not count; the straight line is a least-squares fit.
    """
    mask = image[..., 1] > 128
    ys, xs = np.nonzero(mask)
    assert len(xs) > 100, "the line left the picture"
    flat = np.ptp(xs) >= np.ptp(ys)
    along, across = (xs, ys) if flat else (ys, xs)
    positions = np.unique(along)
    centres = np.array([across[along == p].mean() for p in positions])
    slope, intercept = np.polyfit(positions, centres, 1)
    residual = centres - (slope * positions + intercept)
    return float(np.abs(residual).max() / np.hypot(1.0, slope))


LINES = [
    ((-0.8, -0.55), (0.8, -0.55)),
    ((-0.8, 0.6), (0.8, 0.6)),
    ((-0.6, -0.8), (-0.6, 0.8)),
    ((0.65, -0.8), (0.65, 0.8)),
]


@pytest.mark.parametrize("camera", ["front", "zoom", "stereo", "rear"])
def test_known_distortion_is_straightened(profile: RobotProfile, camera: str) -> None:
    settings = next(c for c in profile.cameras if c.name == camera)
    calibration = settings.calibration
    assert calibration is not None
    undistorter = Undistorter(calibration)
    for start, end in LINES:
        distorted = _distorted_line(calibration, start, end)
        straightened = undistorter.apply(distorted)
        assert straightened.shape == distorted.shape
        bent = _deviation_px(distorted)
        assert bent > 2.0, f"test line {start}-{end} is not visibly bent ({bent:.1f} px)"
        straight = _deviation_px(straightened)
        # Within a pixel of straight (rasterisation), and far straighter than before.
        assert straight < 1.2, (start, end, bent, straight)
        assert straight < bent / 2, (start, end, bent, straight)
