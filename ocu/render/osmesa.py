"""Offscreen OpenGL 3.3 core context in main memory (Mesa's OSMesa, Debian libosmesa6).

Works without any display: the headless fallback of the 3D widget, `ocu screenshot`, the
tests and the benchmarks. PYOPENGL_PLATFORM must be "osmesa" before OpenGL is imported
(ocu.render.platform does that).
"""

from __future__ import annotations

import weakref
from typing import Any

import numpy as np
import numpy.typing as npt

from ocu.render.gl import GL
from ocu.render.platform import active_gl_platform
from ocu.render.renderer import ModelRenderer
from ocu.render.scene import RenderFrame


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


class OffscreenRenderer:
    """A ModelRenderer in its own OSMesa context, with multisampling through an FBO."""

    def __init__(self, renderer: ModelRenderer, width: int, height: int, samples: int = 4):
        self.renderer = renderer
        self.samples = samples
        self.context = OsMesaContext(width, height)
        self._fbo = 0
        self._renderbuffers: list[int] = []
        self._fbo_size = (0, 0)
        renderer.initialize()

    def _ensure_fbo(self) -> None:
        size = (self.context.width, self.context.height)
        if self.samples <= 1 or self._fbo_size == size:
            return
        self._delete_fbo()
        fbo = int(GL.glGenFramebuffers(1))
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, fbo)
        color, depth = (int(v) for v in GL.glGenRenderbuffers(2))
        for buffer, fmt, point in (
            (color, GL.GL_RGBA8, GL.GL_COLOR_ATTACHMENT0),
            (depth, GL.GL_DEPTH_COMPONENT24, GL.GL_DEPTH_ATTACHMENT),
        ):
            GL.glBindRenderbuffer(GL.GL_RENDERBUFFER, buffer)
            GL.glRenderbufferStorageMultisample(GL.GL_RENDERBUFFER, self.samples, fmt, *size)
            GL.glFramebufferRenderbuffer(GL.GL_FRAMEBUFFER, point, GL.GL_RENDERBUFFER, buffer)
        status = GL.glCheckFramebufferStatus(GL.GL_FRAMEBUFFER)
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, 0)
        self._fbo, self._renderbuffers, self._fbo_size = fbo, [color, depth], size
        if status != GL.GL_FRAMEBUFFER_COMPLETE:
            self._delete_fbo()
            self.samples = 1  # render straight into the OSMesa buffer instead

    def _delete_fbo(self) -> None:
        if self._fbo:
            GL.glDeleteFramebuffers(1, [self._fbo])
            GL.glDeleteRenderbuffers(len(self._renderbuffers), self._renderbuffers)
        self._fbo, self._renderbuffers, self._fbo_size = 0, [], (0, 0)

    def render(
        self, frame: RenderFrame, width: int | None = None, height: int | None = None
    ) -> npt.NDArray[np.uint8]:
        """Draw a frame and return it as RGBA rows, top first."""
        self.context.resize(width or self.context.width, height or self.context.height)
        self._ensure_fbo()
        w, h = self.context.width, self.context.height
        if self._fbo:
            GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, self._fbo)
        self.renderer.render(frame, w, h)
        if self._fbo:
            GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, self._fbo)
            GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, 0)
            GL.glBlitFramebuffer(0, 0, w, h, 0, 0, w, h, GL.GL_COLOR_BUFFER_BIT, GL.GL_NEAREST)
            GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, 0)
        return self.context.read_rgba()

    def close(self) -> None:
        """Free the GL objects and the context (idempotent)."""
        if self.context.is_open:
            self.context.make_current()
            self._delete_fbo()
            self.renderer.release()
        self.context.close()
