"""A window's end: its widgets destroyed while Python still runs."""

from __future__ import annotations

from PySide6.QtCore import QCoreApplication, QEvent
from PySide6.QtWidgets import QWidget


def dispose(window: QWidget) -> None:
    """Destroy a shut-down window's widgets now, not at the interpreter's exit.

    Left to the exit, Qt destroyed them while Python was being torn down: a pyqtgraph item's
    Python override (a QGraphicsWidget's event handler) ran then and crashed the process
    (SIGSEGV in shiboken, once in about 20 runs of `ocu screenshot --window`, after the file
    was written).
    """
    window.close()
    window.deleteLater()
    QCoreApplication.sendPostedEvents(None, QEvent.Type.DeferredDelete)
