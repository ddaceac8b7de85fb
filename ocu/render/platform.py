"""Choose PyOpenGL's platform (OSMesa or the native GL of the display) before it is imported."""

from __future__ import annotations

import os
import sys
from collections.abc import Mapping
from typing import Literal

GlMode = Literal["osmesa", "native"]

# Qt platform plugins that give no OpenGL context.
_NO_GL_QPA = ("offscreen", "minimal", "vnc", "linuxfb")


def choose_gl_platform(
    environ: Mapping[str, str] | None = None,
    qt_platform: str | None = None,
    system: str | None = None,
) -> GlMode:
    """'osmesa' when there is no display to draw on with GL, else 'native'.

    An explicit PYOPENGL_PLATFORM wins. On Linux, Qt's offscreen/minimal platforms and a
    session with neither DISPLAY nor WAYLAND_DISPLAY mean OSMesa. `qt_platform` is the running
    QGuiApplication's platformName(), when there is one.
    """
    env = os.environ if environ is None else environ
    explicit = env.get("PYOPENGL_PLATFORM", "")
    if explicit:
        return "osmesa" if explicit == "osmesa" else "native"
    if not (system or sys.platform).startswith("linux"):
        return "native"
    qpa = (qt_platform or env.get("QT_QPA_PLATFORM", "")).split(":")[0].split(";")[0]
    if qpa in _NO_GL_QPA:
        return "osmesa"
    if not env.get("DISPLAY") and not env.get("WAYLAND_DISPLAY"):
        return "osmesa"
    return "native"


def configure_gl_platform(mode: GlMode | None = None) -> GlMode:
    """Make PyOpenGL use `mode` (default: choose_gl_platform()); returns the mode in force.

    PyOpenGL fixes its platform when OpenGL.GL is first imported; after that the mode in force
    is whatever was chosen then, which is what this returns.
    """
    if "OpenGL.platform" in sys.modules:
        return active_gl_platform()
    wanted = mode or choose_gl_platform()
    if wanted == "osmesa":
        os.environ["PYOPENGL_PLATFORM"] = "osmesa"
    return wanted


def active_gl_platform() -> GlMode:
    """The mode PyOpenGL was set up with (only meaningful once OpenGL.GL is imported)."""
    platform = sys.modules.get("OpenGL.platform")
    if platform is None:
        return "osmesa" if os.environ.get("PYOPENGL_PLATFORM") == "osmesa" else "native"
    name = type(getattr(platform, "PLATFORM", None)).__name__
    return "osmesa" if "OSMesa" in name else "native"
