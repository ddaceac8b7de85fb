"""Choose PyOpenGL's platform before it is imported: the display's GL, or offscreen.

Offscreen (no display, or Qt's offscreen platform) draws through Mesa's OSMesa where its
library is installed (Debian's libosmesa6), else through EGL without a surface (Mesa's
surfaceless platform: libegl1 + libegl-mesa0 + libgl1-mesa-dri). Mesa 25.1 removed OSMesa, so
the Debian releases after 13 have only the EGL path; both draw the same picture
(tests/model/test_offscreen_paths.py compares them).
"""

from __future__ import annotations

import ctypes.util
import os
import sys
from collections.abc import Callable, Mapping
from typing import Literal

GlMode = Literal["osmesa", "egl", "native"]
OffscreenMode = Literal["osmesa", "egl"]
OFFSCREEN_MODES: tuple[OffscreenMode, ...] = ("osmesa", "egl")

# Qt platform plugins that give no OpenGL context.
_NO_GL_QPA = ("offscreen", "minimal", "vnc", "linuxfb")


def osmesa_installed(find_library: Callable[[str], str | None] = ctypes.util.find_library) -> bool:
    """Whether Mesa's OSMesa library can be loaded (Debian: libosmesa6)."""
    return find_library("OSMesa") is not None


def offscreen_gl_mode(
    environ: Mapping[str, str] | None = None,
    find_library: Callable[[str], str | None] = ctypes.util.find_library,
) -> OffscreenMode:
    """The offscreen path: PYOPENGL_PLATFORM=osmesa|egl if set, else OSMesa where it is
    installed, else EGL."""
    env = os.environ if environ is None else environ
    explicit = env.get("PYOPENGL_PLATFORM", "")
    if explicit in OFFSCREEN_MODES:
        return "egl" if explicit == "egl" else "osmesa"
    return "osmesa" if osmesa_installed(find_library) else "egl"


def choose_gl_platform(
    environ: Mapping[str, str] | None = None,
    qt_platform: str | None = None,
    system: str | None = None,
    find_library: Callable[[str], str | None] = ctypes.util.find_library,
) -> GlMode:
    """An offscreen mode when there is no display to draw on with GL, else 'native'.

    An explicit PYOPENGL_PLATFORM wins ('osmesa', 'egl'; anything else means the display's).
    On Linux, Qt's offscreen/minimal platforms and a session with neither DISPLAY nor
    WAYLAND_DISPLAY mean offscreen. `qt_platform` is the running QGuiApplication's
    platformName(), when there is one.
    """
    env = os.environ if environ is None else environ
    explicit = env.get("PYOPENGL_PLATFORM", "")
    if explicit:
        return offscreen_gl_mode(env, find_library) if explicit in OFFSCREEN_MODES else "native"
    if not (system or sys.platform).startswith("linux"):
        return "native"
    qpa = (qt_platform or env.get("QT_QPA_PLATFORM", "")).split(":")[0].split(";")[0]
    if qpa in _NO_GL_QPA or (not env.get("DISPLAY") and not env.get("WAYLAND_DISPLAY")):
        return offscreen_gl_mode(env, find_library)
    return "native"


def configure_gl_platform(mode: GlMode | Literal["offscreen"] | None = None) -> GlMode:
    """Make PyOpenGL use `mode` (default: choose_gl_platform(); 'offscreen': the offscreen
    path of offscreen_gl_mode()); returns the mode in force.

    PyOpenGL fixes its platform when OpenGL.GL is first imported; after that the mode in force
    is whatever was chosen then, which is what this returns.
    """
    if "OpenGL.platform" in sys.modules:
        return active_gl_platform()
    wanted: GlMode = offscreen_gl_mode() if mode == "offscreen" else mode or choose_gl_platform()
    if wanted in OFFSCREEN_MODES:
        os.environ["PYOPENGL_PLATFORM"] = wanted
    return wanted


def active_gl_platform() -> GlMode:
    """The mode PyOpenGL was set up with (only meaningful once OpenGL.GL is imported)."""
    platform = sys.modules.get("OpenGL.platform")
    if platform is None:
        explicit = os.environ.get("PYOPENGL_PLATFORM", "")
        return "egl" if explicit == "egl" else "osmesa" if explicit == "osmesa" else "native"
    name = type(getattr(platform, "PLATFORM", None)).__name__
    if "OSMesa" in name:
        return "osmesa"
    return "egl" if "EGL" in name else "native"
