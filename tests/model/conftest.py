"""Fixtures for the model and rendering tests: OSMesa for PyOpenGL, offscreen Qt."""

from __future__ import annotations

import os

# Both must be decided before OpenGL or a QApplication is created.
os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
from ocu.render.platform import offscreen_gl_mode

os.environ.setdefault("PYOPENGL_PLATFORM", offscreen_gl_mode())

from collections.abc import Iterator

import pytest

from ocu.model.urdf import RobotModel, load_urdf
from ocu.render.offscreen import OffscreenRenderer
from ocu.render.renderer import ModelRenderer


@pytest.fixture(scope="session")
def engineer() -> RobotModel:
    """The shipped low-poly Engineer (treat as read-only: copy its tree to pose it)."""
    return load_urdf()


@pytest.fixture
def offscreen(engineer: RobotModel) -> Iterator[OffscreenRenderer]:
    """An OSMesa renderer of the Engineer at 320x240 without multisampling."""
    renderer = OffscreenRenderer(ModelRenderer(engineer), 320, 240, samples=1)
    yield renderer
    renderer.close()
