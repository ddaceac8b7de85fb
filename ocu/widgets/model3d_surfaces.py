"""The two surfaces the 3D view (ocu.widgets.model3d) draws on: the display's OpenGL in a
QOpenGLWidget, or an offscreen context (OSMesa or EGL) rendering on a thread of its own,
whose image a plain QWidget paints."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from PySide6.QtCore import QElapsedTimer, Qt, QTimer
from PySide6.QtGui import QImage, QPainter, QPaintEvent, QResizeEvent, QSurfaceFormat
from PySide6.QtOpenGLWidgets import QOpenGLWidget
from PySide6.QtWidgets import QWidget

from ocu.qt.inbox import to_gui
from ocu.render.scene import RenderFrame

if TYPE_CHECKING:
    from ocu.widgets.model3d import Model3DWidget

log = logging.getLogger("ocu.widgets")

SOFTWARE_FRAME_INTERVAL_MS = 33  # at most ~30 OSMesa frames per second
# A frame waited for (render_now) gives up after this; the render thread's end is waited
# for this long when the view is released.
RENDER_WAIT_S = 10.0
RENDER_JOIN_TIMEOUT_S = 5.0


def _gl_surface_format() -> QSurfaceFormat:
    fmt = QSurfaceFormat()
    fmt.setRenderableType(QSurfaceFormat.RenderableType.OpenGL)
    fmt.setVersion(3, 3)
    fmt.setProfile(QSurfaceFormat.OpenGLContextProfile.CoreProfile)
    fmt.setDepthBufferSize(24)
    fmt.setSamples(4)
    return fmt


class GlSurface(QOpenGLWidget):
    """Native path: the renderer draws into Qt's framebuffer in paintGL."""

    def __init__(self, owner: Model3DWidget) -> None:
        super().__init__(owner)
        from ocu.render.renderer import ModelRenderer  # after the platform choice

        self._owner = owner
        self.setFormat(_gl_surface_format())
        self.renderer = ModelRenderer(owner.model)
        owner.install_overlays(self.renderer)
        self.frames_rendered = 0
        self.error: str | None = None

    def initializeGL(self) -> None:
        from ocu.render.renderer import RenderError

        context = self.context()
        if context is None or not context.isValid():
            self.error = "3D view unavailable: no OpenGL context"
            return
        fmt = context.format()
        if (fmt.majorVersion(), fmt.minorVersion()) < (3, 3):
            self.error = (
                f"3D view unavailable: OpenGL 3.3 needed, got "
                f"{fmt.majorVersion()}.{fmt.minorVersion()}"
            )
            return
        try:
            self.renderer.initialize()
        except RenderError as err:
            self.error = f"3D view unavailable: {err}"
            return
        context.aboutToBeDestroyed.connect(self.release)

    def paintGL(self) -> None:
        if self.error is not None or not self.renderer.initialized:
            return
        ratio = self.devicePixelRatioF()
        width = round(self.width() * ratio)
        height = round(self.height() * ratio)
        self.renderer.render(self._owner.build_frame(width, height), width, height)
        self.frames_rendered += 1
        self._owner._surface_rendered()

    def request_render(self) -> None:
        self.update()

    def render_now(self) -> None:
        self.repaint()

    def release(self) -> None:
        if self.renderer.initialized and self.context() is not None:
            self.makeCurrent()
            self.renderer.release()
            self.doneCurrent()


class RenderThread:
    """The offscreen renderer on a thread of its own ("ocu-render").

    The OSMesa or EGL context is made and kept current there. PyOpenGL calls GL through ctypes,
    which lets go of the interpreter lock for each call, so a software frame (tens of ms in
    llvmpipe) no longer holds the GUI thread, nor the GIL the control thread and the keys
    need, for its length. The GUI thread builds each frame (cheap: matrices) and hands it
    over; a newer frame replaces one not started yet; the pixels come back through the GUI
    inbox (ocu.qt.inbox).
    """

    def __init__(
        self,
        make: Callable[[int, int], Any],
        deliver: Callable[[int, bytes, int, int, str | None], None],
    ) -> None:
        self._make = make
        self._deliver = deliver
        self._cond = threading.Condition()
        self._job: tuple[int, RenderFrame, int, int] | None = None
        self._closing = False
        self._done = 0  # the id of the newest job rendered (or failed)
        self._result: tuple[int, bytes, int, int, str | None] | None = None
        # Held while a frame renders; the GUI thread takes it to change what the renderer
        # draws (its overlay meshes).
        self.lock = threading.Lock()
        self.offscreen: Any = None
        self.error: str | None = None
        self._thread = threading.Thread(target=self._run, name="ocu-render", daemon=True)
        self._thread.start()

    def submit(self, job_id: int, frame: RenderFrame, width: int, height: int) -> None:
        """Render this frame next (a frame still waiting is dropped)."""
        with self._cond:
            self._job = (job_id, frame, width, height)
            self._cond.notify_all()

    def wait(self, job_id: int, timeout_s: float) -> tuple[int, bytes, int, int, str | None] | None:
        """The newest result once job `job_id` is done (None after `timeout_s`)."""
        with self._cond:
            self._cond.wait_for(lambda: self._done >= job_id or self._closing, timeout_s)
            return self._result if self._done >= job_id else None

    def close(self) -> None:
        """Stop the thread and free the context (on the thread that made it)."""
        with self._cond:
            self._closing = True
            self._cond.notify_all()
        if self._thread is not threading.current_thread():
            self._thread.join(RENDER_JOIN_TIMEOUT_S)

    def _run(self) -> None:
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._job is not None or self._closing)
                if self._closing:
                    break
                assert self._job is not None
                job_id, frame, width, height = self._job
                self._job = None
            result = self._render(job_id, frame, width, height)
            with self._cond:
                self._result = result
                self._done = job_id
                self._cond.notify_all()
            self._deliver(*result)
        with self.lock:
            if self.offscreen is not None:
                self.offscreen.close()
                self.offscreen = None

    def _render(
        self, job_id: int, frame: RenderFrame, width: int, height: int
    ) -> tuple[int, bytes, int, int, str | None]:
        with self.lock:
            try:
                if self.error is not None:
                    return job_id, b"", width, height, self.error
                if self.offscreen is None:
                    self.offscreen = self._make(width, height)
                rgba = self.offscreen.render(frame, width, height)
                return job_id, rgba.tobytes(), width, height, None
            except Exception as err:  # no OSMesa, or a GL failure: show why, do not crash
                log.exception("the 3D view's offscreen renderer failed")
                self.error = f"3D view unavailable: {err}"
                return job_id, b"", width, height, self.error


class SoftwareSurface(QWidget):
    """OSMesa/EGL path: render offscreen on a rate-limited timer (on the render thread),
    paint the image."""

    def __init__(self, owner: Model3DWidget) -> None:
        super().__init__(owner)
        self._owner = owner
        self._image = QImage()
        self.renderer: Any = None
        self.frames_rendered = 0
        self.error: str | None = None
        self._since_last = QElapsedTimer()
        self._timer = QTimer(self)
        self._timer.setSingleShot(True)
        self._timer.timeout.connect(self._render_async)
        self.setAttribute(Qt.WidgetAttribute.WA_OpaquePaintEvent)
        self._thread: RenderThread | None = None
        self._jobs = 0
        self._applied = 0
        self._busy = False  # a frame is being rendered: the next waits for it
        self._pending = False  # asked for while busy: rendered when the current one is shown
        self._released = False

    @property
    def _offscreen(self) -> Any:
        return self._thread.offscreen if self._thread is not None else None

    def _make(self, width: int, height: int) -> Any:
        # On the render thread: the context is current there.
        from ocu.render.offscreen import OffscreenRenderer

        return OffscreenRenderer(self.renderer, width, height)

    def _ensure_thread(self) -> bool:
        if self.error is not None or self._released:
            return False
        if self._thread is None:
            try:
                from ocu.render.renderer import ModelRenderer

                self.renderer = ModelRenderer(self._owner.model)
                self._owner.install_overlays(self.renderer)
            except Exception as err:  # no GL library at all: show why instead of crashing
                self.error = f"3D view unavailable: {err}"
                self.update()
                return False
            thread = RenderThread(self._make, to_gui(self._apply))
            # A view deleted without release() ends its thread too (a plain callable: the
            # surface's Python side may be gone by then).
            self.destroyed.connect(thread.close)
            self._thread = thread
        return True

    @property
    def render_lock(self) -> threading.Lock | None:
        """Held while the render thread draws (None before it exists)."""
        return self._thread.lock if self._thread is not None else None

    def _pixel_size(self) -> tuple[int, int]:
        ratio = self.devicePixelRatioF()
        return max(round(self.width() * ratio), 1), max(round(self.height() * ratio), 1)

    def request_render(self) -> None:
        if self._timer.isActive():
            return
        elapsed = self._since_last.elapsed() if self._since_last.isValid() else 1 << 30
        self._timer.start(max(0, SOFTWARE_FRAME_INTERVAL_MS - int(elapsed)))

    def _submit(self) -> int:
        assert self._thread is not None
        width, height = self._pixel_size()
        self._jobs += 1
        self._thread.submit(self._jobs, self._owner.build_frame(width, height), width, height)
        self._since_last.start()
        return self._jobs

    def _render_async(self) -> None:
        if not self._ensure_thread():
            return
        if self._busy:
            # One frame at a time: the next starts when this one is shown (no queue).
            self._pending = True
            return
        self._busy = True
        self._pending = False
        self._submit()

    def render_now(self) -> None:
        """Draw the current state and wait for it (screenshots, tests)."""
        self._timer.stop()
        if not self._ensure_thread():
            return
        assert self._thread is not None
        job = self._submit()
        result = self._thread.wait(job, RENDER_WAIT_S)
        if result is None:
            log.warning("the 3D view's frame took longer than %.0f s", RENDER_WAIT_S)
            return
        self._apply(*result)

    def _apply(self, job_id: int, data: bytes, width: int, height: int, error: str | None) -> None:
        # GUI thread.
        if self._thread is None or job_id <= self._applied:
            return
        self._applied = job_id
        if job_id >= self._jobs:
            self._busy = False
        if error is not None:
            self.error = error
            self.update()
            return
        image = QImage(data, width, height, width * 4, QImage.Format.Format_RGBA8888)
        self._image = image.copy()  # own the pixels
        self._image.setDevicePixelRatio(self.devicePixelRatioF())
        self.frames_rendered += 1
        self.update()
        self._owner._surface_rendered()
        if self._pending:
            self._pending = False
            self.request_render()

    def paintEvent(self, event: QPaintEvent) -> None:
        painter = QPainter(self)
        if self._image.isNull() or self.error is not None:
            painter.fillRect(self.rect(), Qt.GlobalColor.darkGray)
            if self.error is not None:
                painter.setPen(Qt.GlobalColor.white)
                painter.drawText(
                    self.rect(),
                    Qt.AlignmentFlag.AlignCenter | Qt.TextFlag.TextWordWrap,
                    self.error,
                )
        else:
            painter.drawImage(0, 0, self._image)
        painter.end()

    def resizeEvent(self, event: QResizeEvent) -> None:
        super().resizeEvent(event)
        self.request_render()

    def release(self) -> None:
        self._timer.stop()
        self._released = True
        thread, self._thread = self._thread, None
        if thread is not None:
            thread.close()
