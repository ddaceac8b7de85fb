"""Offscreen OpenGL 3.3 core context in main memory (Mesa's OSMesa, Debian libosmesa6).

Works without any display: the headless fallback of the 3D widget, `ocu screenshot`, the
tests and the benchmarks, where Mesa still ships it (Debian 12 and 13: libosmesa6; Mesa 25.1
removed it, and ocu.render.egl takes over). PYOPENGL_PLATFORM must be "osmesa" before OpenGL
is imported (ocu.render.platform does that).
"""

from __future__ import annotations

import weakref
from typing import Any

import numpy as np
import numpy.typing as npt

from ocu.render.gl import GL
from ocu.render.platform import active_gl_platform


class OsMesaError(RuntimeError):
    """No OSMesa context could be made (library missing, or another GL platform in force)."""


def _osmesa() -> Any:
    if active_gl_platform() != "osmesa":
        raise OsMesaError(
            "PyOpenGL was set up for the native GL platform; set PYOPENGL_PLATFORM=osmesa "
            "before OpenGL is imported to render offscreen"
        )
    try:
        from OpenGL import osmesa  # importable on the OSMesa platform only
    except Exception as err:
        raise OsMesaError(f"OSMesa is not available: {err}") from err
    return osmesa


def _destroy(osmesa: Any, context: Any) -> None:
    osmesa.OSMesaDestroyContext(context)


class OsMesaContext:
    """A GL 3.3 core context drawing into a numpy RGBA buffer."""

    name = "osmesa"
    framebuffer = 0  # the context's own buffer is the default framebuffer

    def __init__(self, width: int, height: int) -> None:
        osmesa = _osmesa()
        self._osmesa = osmesa
        attributes = [
            osmesa.OSMESA_FORMAT, osmesa.OSMESA_RGBA,
            osmesa.OSMESA_DEPTH_BITS, 24,
            osmesa.OSMESA_STENCIL_BITS, 0,
            osmesa.OSMESA_ACCUM_BITS, 0,
            osmesa.OSMESA_PROFILE, osmesa.OSMESA_CORE_PROFILE,
            osmesa.OSMESA_CONTEXT_MAJOR_VERSION, 3,
            osmesa.OSMESA_CONTEXT_MINOR_VERSION, 3,
            0,
        ]  # fmt: skip
        array = (GL.GLint * len(attributes))(*attributes)
        try:
            context = osmesa.OSMesaCreateContextAttribs(array, None)
        except Exception as err:
            raise OsMesaError(f"cannot create an OSMesa context: {err}") from err
        if not context:
            raise OsMesaError("cannot create an OSMesa GL 3.3 core context")
        self._context = context
        self._finalizer = weakref.finalize(self, _destroy, osmesa, context)
        self.width = 0
        self.height = 0
        self._buffer: npt.NDArray[np.uint8] = np.zeros((0, 0, 4), dtype=np.uint8)
        self.resize(width, height)

    @property
    def renderer_name(self) -> str:
        """The GL renderer's name (e.g. 'llvmpipe (LLVM 15.0.6, 256 bits)')."""
        self.make_current()
        name = GL.glGetString(GL.GL_RENDERER)
        return name.decode(errors="replace") if isinstance(name, bytes) else str(name)

    def resize(self, width: int, height: int) -> None:
        """New buffer size; makes the context current."""
        width, height = max(int(width), 1), max(int(height), 1)
        if (width, height) != (self.width, self.height):
            self._buffer = np.zeros((height, width, 4), dtype=np.uint8)
            self.width, self.height = width, height
        self.make_current()

    @property
    def is_open(self) -> bool:
        """Whether the context still exists."""
        return bool(self._finalizer.alive)

    def make_current(self) -> None:
        """Make this context current on the calling thread, drawing into its buffer."""
        if not self.is_open:
            raise OsMesaError("the OSMesa context was closed")
        ok = self._osmesa.OSMesaMakeCurrent(
            self._context, self._buffer, GL.GL_UNSIGNED_BYTE, self.width, self.height
        )
        if not ok:
            raise OsMesaError("OSMesaMakeCurrent failed")

    def read_rgba(self) -> npt.NDArray[np.uint8]:
        """The finished image, top row first, (height, width, 4)."""
        GL.glFinish()
        return np.ascontiguousarray(self._buffer[::-1])

    def close(self) -> None:
        """Destroy the context (idempotent)."""
        self._finalizer()
