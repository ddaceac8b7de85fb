"""Offscreen OpenGL 3.3 core context through EGL without any surface (Mesa's surfaceless
platform, EGL_MESA_platform_surfaceless), drawing into a framebuffer object of its own.

The offscreen path where OSMesa is missing (Mesa 25.1 removed it). PYOPENGL_PLATFORM must be
"egl" before OpenGL is imported (ocu.render.platform does that). Debian packages: libegl1
(the dispatcher), libegl-mesa0 (Mesa's EGL) and libgl1-mesa-dri (llvmpipe, Mesa's software
rasteriser).
"""

from __future__ import annotations

import ctypes
import weakref
from typing import Any

import numpy as np
import numpy.typing as npt

from ocu.render.gl import GL
from ocu.render.platform import active_gl_platform

# EGL_MESA_platform_surfaceless: a display with no window system at all.
EGL_PLATFORM_SURFACELESS_MESA = 0x31DD


class EglError(RuntimeError):
    """No EGL context could be made (library missing, or another GL platform in force)."""


def _egl() -> Any:
    if active_gl_platform() != "egl":
        raise EglError(
            "PyOpenGL was set up for another GL platform; set PYOPENGL_PLATFORM=egl "
            "before OpenGL is imported to render through EGL"
        )
    try:
        from OpenGL import EGL  # loads libEGL on the EGL platform
    except Exception as err:
        raise EglError(f"EGL is not available: {err}") from err
    return EGL


def _surfaceless_display(egl: Any) -> Any:
    extensions = egl.eglQueryString(egl.EGL_NO_DISPLAY, egl.EGL_EXTENSIONS) or b""
    if b"EGL_MESA_platform_surfaceless" not in extensions:
        raise EglError(
            "EGL has no surfaceless platform (EGL_MESA_platform_surfaceless): install Mesa's "
            "EGL (Debian: libegl-mesa0 libgl1-mesa-dri)"
        )
    display = egl.eglGetPlatformDisplayEXT(
        EGL_PLATFORM_SURFACELESS_MESA, egl.EGL_DEFAULT_DISPLAY, None
    )
    if not display:
        raise EglError("eglGetPlatformDisplayEXT found no surfaceless display")
    major, minor = egl.EGLint(), egl.EGLint()
    if not egl.eglInitialize(display, ctypes.pointer(major), ctypes.pointer(minor)):
        raise EglError("eglInitialize failed on the surfaceless display")
    return display


def _destroy(egl: Any, display: Any, context: Any, framebuffer: list[int]) -> None:
    # The GL objects go with the context; only the context and display are released here.
    framebuffer.clear()
    egl.eglMakeCurrent(display, egl.EGL_NO_SURFACE, egl.EGL_NO_SURFACE, egl.EGL_NO_CONTEXT)
    egl.eglDestroyContext(display, context)
    egl.eglTerminate(display)


class EglContext:
    """A GL 3.3 core context drawing into an RGBA framebuffer object of its own."""

    name = "egl"

    def __init__(self, width: int, height: int) -> None:
        egl = _egl()
        self._egl = egl
        try:
            display = _surfaceless_display(egl)
        except EglError:
            raise
        except Exception as err:
            raise EglError(f"cannot open an EGL display: {err}") from err
        config = egl.EGLConfig()
        count = egl.EGLint()
        wanted = (egl.EGLint * 5)(
            egl.EGL_SURFACE_TYPE, egl.EGL_PBUFFER_BIT,
            egl.EGL_RENDERABLE_TYPE, egl.EGL_OPENGL_BIT,
            egl.EGL_NONE,
        )  # fmt: skip
        if not egl.eglChooseConfig(display, wanted, ctypes.pointer(config), 1, count):
            egl.eglTerminate(display)
            raise EglError("eglChooseConfig failed")
        if not egl.eglBindAPI(egl.EGL_OPENGL_API):
            egl.eglTerminate(display)
            raise EglError("EGL cannot bind the desktop OpenGL API")
        attributes = (egl.EGLint * 7)(
            egl.EGL_CONTEXT_MAJOR_VERSION, 3,
            egl.EGL_CONTEXT_MINOR_VERSION, 3,
            egl.EGL_CONTEXT_OPENGL_PROFILE_MASK, egl.EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT,
            egl.EGL_NONE,
        )  # fmt: skip
        context = egl.eglCreateContext(
            display, config if count.value else egl.EGLConfig(), egl.EGL_NO_CONTEXT, attributes
        )
        if not context:
            egl.eglTerminate(display)
            raise EglError("cannot create an EGL GL 3.3 core context")
        self._display = display
        self._context = context
        self._objects: list[int] = []  # [fbo, color renderbuffer, depth renderbuffer]
        self._finalizer = weakref.finalize(self, _destroy, egl, display, context, self._objects)
        self.width = 0
        self.height = 0
        self.resize(width, height)

    @property
    def framebuffer(self) -> int:
        """The framebuffer object that stands for the window's (0 would be no surface)."""
        return self._objects[0] if self._objects else 0

    @property
    def renderer_name(self) -> str:
        """The GL renderer's name (e.g. 'llvmpipe (LLVM 15.0.6, 256 bits)')."""
        self.make_current()
        name = GL.glGetString(GL.GL_RENDERER)
        return name.decode(errors="replace") if isinstance(name, bytes) else str(name)

    def resize(self, width: int, height: int) -> None:
        """New framebuffer size; makes the context current."""
        width, height = max(int(width), 1), max(int(height), 1)
        self.make_current()
        if (width, height) == (self.width, self.height) and self._objects:
            return
        self._delete_objects()
        fbo = int(GL.glGenFramebuffers(1))
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, fbo)
        color, depth = (int(v) for v in GL.glGenRenderbuffers(2))
        for buffer, fmt, point in (
            (color, GL.GL_RGBA8, GL.GL_COLOR_ATTACHMENT0),
            (depth, GL.GL_DEPTH_COMPONENT24, GL.GL_DEPTH_ATTACHMENT),
        ):
            GL.glBindRenderbuffer(GL.GL_RENDERBUFFER, buffer)
            GL.glRenderbufferStorage(GL.GL_RENDERBUFFER, fmt, width, height)
            GL.glFramebufferRenderbuffer(GL.GL_FRAMEBUFFER, point, GL.GL_RENDERBUFFER, buffer)
        status = GL.glCheckFramebufferStatus(GL.GL_FRAMEBUFFER)
        self._objects[:] = [fbo, color, depth]
        if status != GL.GL_FRAMEBUFFER_COMPLETE:
            self._delete_objects()
            raise EglError(f"the EGL framebuffer is incomplete (status 0x{int(status):x})")
        self.width, self.height = width, height

    def _delete_objects(self) -> None:
        if self._objects:
            GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, 0)
            GL.glDeleteFramebuffers(1, [self._objects[0]])
            GL.glDeleteRenderbuffers(2, self._objects[1:])
            self._objects.clear()

    @property
    def is_open(self) -> bool:
        """Whether the context still exists."""
        return bool(self._finalizer.alive)

    def make_current(self) -> None:
        """Make this context current on the calling thread, drawing into its framebuffer."""
        if not self.is_open:
            raise EglError("the EGL context was closed")
        egl = self._egl
        if not egl.eglMakeCurrent(self._display, egl.EGL_NO_SURFACE, egl.EGL_NO_SURFACE,
                                  self._context):  # fmt: skip
            raise EglError("eglMakeCurrent failed")
        if self._objects:
            GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, self._objects[0])

    def read_rgba(self) -> npt.NDArray[np.uint8]:
        """The finished image, top row first, (height, width, 4)."""
        GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, self.framebuffer)
        GL.glPixelStorei(GL.GL_PACK_ALIGNMENT, 1)
        data = GL.glReadPixels(0, 0, self.width, self.height, GL.GL_RGBA, GL.GL_UNSIGNED_BYTE)
        raw = data if isinstance(data, bytes) else bytes(data)
        image = np.frombuffer(raw, dtype=np.uint8).reshape(self.height, self.width, 4)
        return np.ascontiguousarray(image[::-1])

    def close(self) -> None:
        """Destroy the framebuffer and the context (idempotent)."""
        if self.is_open:
            self.make_current()
            self._delete_objects()
        self._finalizer()
