"""Orbit camera and GL platform choice: plain functions, no GL context needed."""

from __future__ import annotations

import numpy as np
import pytest

from ocu.render.camera import OrbitCamera
from ocu.render.platform import choose_gl_platform


def _camera() -> OrbitCamera:
    return OrbitCamera.framing((-0.5, -0.3, 0.0), (0.5, 0.3, 0.6), "iso")


def test_front_view_looks_back_along_x_with_z_up() -> None:
    camera = _camera()
    camera.set_view("front")
    eye = camera.eye()
    assert eye[0] > 0
    assert abs(eye[1] - camera.target[1]) < 1e-9
    view = camera.view_matrix()
    assert np.allclose(view[:3, :3] @ [0, 0, 1], [0, 1, 0])  # world up is screen up
    assert np.allclose(view[:3, :3] @ [0, 1, 0], [1, 0, 0])  # robot's left on screen right


def test_side_view_shows_forward_to_the_right_and_top_view_forward_up() -> None:
    camera = _camera()
    w, h = 400, 300
    centre = camera.target
    camera.set_view("side")
    ahead = camera.project([centre + np.array([0.3, 0.0, 0.0])], w, h)[0]
    assert ahead[0] > w / 2 + 10
    assert abs(ahead[1] - h / 2) < 1
    camera.set_view("top")
    ahead = camera.project([centre + np.array([0.3, 0.0, 0.0])], w, h)[0]
    assert ahead[1] < h / 2 - 10
    assert abs(ahead[0] - w / 2) < 1


def test_target_projects_to_the_centre_and_eye_matches_the_view() -> None:
    camera = _camera()
    for azimuth, elevation in ((10.0, 20.0), (-120.0, -30.0), (180.0, 90.0)):
        camera.azimuth_deg, camera.elevation_deg = azimuth, elevation
        assert np.allclose(camera.project([camera.target], 640, 480)[0], [320, 240])
        assert np.allclose(np.linalg.inv(camera.view_matrix())[:3, 3], camera.eye())


def test_orbit_pan_zoom_and_reset() -> None:
    camera = _camera()
    start = (camera.azimuth_deg, camera.elevation_deg, camera.distance)
    camera.orbit(100, 0)
    assert camera.azimuth_deg == pytest.approx(start[0] - 40.0)
    camera.orbit(0, 10_000)
    assert camera.elevation_deg == 90.0  # clamped: straight down, never over the top
    camera.zoom(2)
    assert camera.distance == pytest.approx(start[2] * 0.85**2)
    target = camera.target.copy()
    camera.set_view("front")
    camera.pan(50, 0, 300)
    moved = camera.target - target
    assert moved[1] < 0
    assert abs(moved[0]) < 1e-9
    assert abs(moved[2]) < 1e-9
    camera.reset()
    assert (camera.azimuth_deg, camera.elevation_deg, camera.distance) == start
    assert np.allclose(camera.target, target)


def test_pan_keeps_the_grabbed_point_under_the_cursor() -> None:
    camera = _camera()
    w, h = 400, 300
    point = camera.target.copy()
    before = camera.project([point], w, h)[0]
    camera.pan(30, -20, h)
    after = camera.project([point], w, h)[0]
    assert np.allclose(after - before, [30, -20], atol=0.5)


def test_unknown_view_is_refused() -> None:
    with pytest.raises(ValueError, match="unknown view 'back'"):
        _camera().set_view("back")


def _with_osmesa(name: str) -> str | None:
    return "libOSMesa.so.8"


def _without_osmesa(name: str) -> str | None:
    return None


@pytest.mark.parametrize(
    ("environ", "qt_platform", "system", "expected"),
    [
        ({"PYOPENGL_PLATFORM": "osmesa", "DISPLAY": ":0"}, None, "linux", "osmesa"),
        ({"PYOPENGL_PLATFORM": "egl", "DISPLAY": ":0"}, None, "linux", "egl"),
        ({"PYOPENGL_PLATFORM": "glx"}, None, "linux", "native"),
        ({"QT_QPA_PLATFORM": "offscreen", "DISPLAY": ":0"}, None, "linux", "osmesa"),
        ({"DISPLAY": ":0"}, "minimal", "linux", "osmesa"),
        ({}, None, "linux", "osmesa"),
        ({"DISPLAY": ":0"}, None, "linux", "native"),
        ({"WAYLAND_DISPLAY": "wayland-0"}, "wayland", "linux", "native"),
        ({"QT_QPA_PLATFORM": "xcb", "DISPLAY": ":1"}, "xcb", "linux", "native"),
        ({}, None, "win32", "native"),
        ({}, None, "darwin", "native"),
    ],
)
def test_gl_platform_choice(
    environ: dict[str, str], qt_platform: str | None, system: str, expected: str
) -> None:
    assert choose_gl_platform(environ, qt_platform, system, _with_osmesa) == expected


@pytest.mark.parametrize(
    ("environ", "expected"),
    [
        ({}, "egl"),
        ({"QT_QPA_PLATFORM": "offscreen", "DISPLAY": ":0"}, "egl"),
        ({"PYOPENGL_PLATFORM": "osmesa"}, "osmesa"),
        ({"DISPLAY": ":0"}, "native"),
    ],
)
def test_without_osmesa_offscreen_drawing_goes_through_egl(
    environ: dict[str, str], expected: str
) -> None:
    # Mesa 25.1 removed OSMesa: the Debian after 13 has no libosmesa6.
    assert choose_gl_platform(environ, None, "linux", _without_osmesa) == expected
