"""The one place that imports PyOpenGL, after its platform has been chosen."""

from ocu.render.platform import configure_gl_platform

configure_gl_platform()

from OpenGL import GL  # noqa: E402

__all__ = ["GL"]
