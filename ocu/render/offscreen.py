"""Drawing without a display: the renderer in an offscreen context, OSMesa's or EGL's.

Which one is PyOpenGL's platform, chosen once per process by ocu.render.platform (OSMesa where
its library is installed, else EGL's surfaceless platform); `describe()` says which one drew,
for `ocu screenshot` and the 3D view's status.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
import numpy.typing as npt

from ocu.render.gl import GL
from ocu.render.platform import active_gl_platform
from ocu.render.renderer import ModelRenderer
from ocu.render.scene import RenderFrame


class OffscreenContext(Protocol):
    """What the renderer needs of an offscreen GL context."""

    name: str
    width: int
    height: int

    @property
    def framebuffer(self) -> int: ...

    @property
    def renderer_name(self) -> str: ...

    @property
    def is_open(self) -> bool: ...

    def resize(self, width: int, height: int) -> None: ...

    def make_current(self) -> None: ...

    def read_rgba(self) -> npt.NDArray[np.uint8]: ...

    def close(self) -> None: ...


class OffscreenError(RuntimeError):
    """No offscreen GL context could be made on this machine."""


def open_offscreen_context(width: int, height: int) -> OffscreenContext:
    """A GL 3.3 core context of PyOpenGL's platform (OSMesa or EGL), current on this thread."""
    mode = active_gl_platform()
    if mode == "egl":
        from ocu.render.egl import EglContext, EglError

        try:
            return EglContext(width, height)
        except EglError as err:
            raise OffscreenError(f"{err} (offscreen drawing through EGL)") from err
    if mode == "osmesa":
        from ocu.render.osmesa import OsMesaContext, OsMesaError

        try:
            return OsMesaContext(width, height)
        except OsMesaError as err:
            raise OffscreenError(f"{err} (offscreen drawing through OSMesa)") from err
    raise OffscreenError(
        "PyOpenGL was set up for the display's GL; set PYOPENGL_PLATFORM=osmesa or egl "
        "before OpenGL is imported to render offscreen"
    )


class OffscreenRenderer:
    """A ModelRenderer in its own offscreen context, with multisampling through an FBO."""

    def __init__(self, renderer: ModelRenderer, width: int, height: int, samples: int = 4):
        self.renderer = renderer
        self.samples = samples
        self.context = open_offscreen_context(width, height)
        self._fbo = 0
        self._renderbuffers: list[int] = []
        self._fbo_size = (0, 0)
        renderer.initialize()

    def describe(self) -> str:
        """Which path draws, e.g. 'EGL (llvmpipe (LLVM 15.0.6, 256 bits))'."""
        path = {"egl": "EGL", "osmesa": "OSMesa"}.get(self.context.name, self.context.name)
        return f"{path} ({self.context.renderer_name})"

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
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, self.context.framebuffer)
        self._fbo, self._renderbuffers, self._fbo_size = fbo, [color, depth], size
        if status != GL.GL_FRAMEBUFFER_COMPLETE:
            self._delete_fbo()
            self.samples = 1  # render straight into the context's framebuffer instead

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
        target = self.context.framebuffer
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, self._fbo or target)
        self.renderer.render(frame, w, h)
        if self._fbo:
            GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, self._fbo)
            GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, target)
            GL.glBlitFramebuffer(0, 0, w, h, 0, 0, w, h, GL.GL_COLOR_BUFFER_BIT, GL.GL_NEAREST)
            GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, target)
        return self.context.read_rgba()

    def close(self) -> None:
        """Free the GL objects and the context (idempotent)."""
        if self.context.is_open:
            self.context.make_current()
            self._delete_fbo()
            self.renderer.release()
        self.context.close()
