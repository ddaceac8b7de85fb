"""Record a link session to an MCAP file: raw datagrams and decoded ROS 2 messages.

The recorder is one more subscriber of a Link (attach()). Its callbacks run
on the link's threads and only append to a bounded queue: when the queue is full the item is
dropped and counted, the link never waits. A named writer thread ("ocu-record") turns items
into CDR messages and writes them with the mcap package's Writer, in chunks that are closed
by size (chunk_size) and by time (flush_period_s) and handed to the operating system at once,
so a recorder killed with SIGKILL leaves a file readable up to its last complete chunk. A
write error (disk full, file too large, I/O error) stops the recording with a message; the
link goes on.

Time stamps: every time is the link's monotonic clock, mapped to wall-clock nanoseconds
through one (wall, monotonic) pair read when the recording starts, so log times are
monotonic and comparable with other wall-clock logs. See docs/recordings.md.
"""

from __future__ import annotations

import logging
import os
import shutil
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from mcap.writer import CompressionType

from ocu.link.base import Link
from ocu.profile import RobotProfile
from ocu.record import schemas as s
from ocu.record.convert import EVENT, VIDEO, Item, item_of
from ocu.record.errors import RecordingError
from ocu.record.session import RecordingFile
from ocu.records import LinkEvent

log = logging.getLogger("ocu.record")

DEFAULT_CHUNK_BYTES = 1024 * 1024
DEFAULT_FLUSH_PERIOD_S = 1.0
DEFAULT_MAX_QUEUE_BYTES = 64 * 1024 * 1024
DEFAULT_MIN_FREE_BYTES = 16 * 1024 * 1024
# The writer wakes this often, or sooner once a quarter of the queue bound is waiting.
BATCH_PERIOD_S = 0.05
# Callbacks arrive from more than one thread (a command is sent from the GUI thread, the tick
# from the link loop): items are held this long and written in time order.
REORDER_HOLD_S = 0.1
STOP_TIMEOUT_S = 10.0
# Rough bytes of a queued item beside its payload, for the queue's memory bound.
ITEM_OVERHEAD_BYTES = 200
RECORDINGS_DIR_ENV = "OCU_RECORDINGS_DIR"


def default_recordings_dir() -> Path:
    """$OCU_RECORDINGS_DIR, else $XDG_DATA_HOME/ocu/recordings, else ~/.local/share/..."""
    if os.environ.get(RECORDINGS_DIR_ENV):
        return Path(os.environ[RECORDINGS_DIR_ENV])
    base = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
    return Path(base) / "ocu" / "recordings"


def timestamped_name(wall_s: float | None = None) -> str:
    """A file name for a new recording: ocu-YYYYmmdd-HHMMSS.mcap (local time)."""
    moment = time.localtime(time.time() if wall_s is None else wall_s)
    return time.strftime("ocu-%Y%m%d-%H%M%S.mcap", moment)


@dataclass(frozen=True)
class RecorderStats:
    """What the recorder has done so far (or did, once stopped)."""

    recording: bool
    path: Path | None
    elapsed_s: float
    messages_written: int
    bytes_written: int
    dropped: int
    queued_bytes: int
    error: str | None


class Recorder:
    """Writes what one or more links send and receive to an MCAP file, off their threads.

    attach(link) any number of links; start(path) and stop() any number of times; stop() is
    idempotent.
    `on_error(message)` is called from the writer thread when a write error ends a recording.
    """

    def __init__(
        self,
        profile: RobotProfile,
        *,
        chunk_bytes: int = DEFAULT_CHUNK_BYTES,
        flush_period_s: float = DEFAULT_FLUSH_PERIOD_S,
        max_queue_bytes: int = DEFAULT_MAX_QUEUE_BYTES,
        min_free_bytes: int = DEFAULT_MIN_FREE_BYTES,
        compression: CompressionType = CompressionType.ZSTD,
        decoded_video: bool = True,
        on_error: Callable[[str], None] | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if chunk_bytes < 1 or flush_period_s <= 0.0 or max_queue_bytes < 1:
            raise ValueError("chunk_bytes, flush_period_s and max_queue_bytes must be positive")
        self.profile = profile
        self.chunk_bytes = chunk_bytes
        self.flush_period_s = flush_period_s
        self.max_queue_bytes = max_queue_bytes
        self.min_free_bytes = min_free_bytes
        self.compression = compression
        self.decoded_video = decoded_video
        self.on_error = on_error
        self.clock = clock

        self._control = threading.Lock()
        self._cond = threading.Condition()
        self._queue: deque[Item] = deque()
        self._queued_bytes = 0
        self._accepting = False
        self._stopping = False
        self._dropped = 0
        self._thread: threading.Thread | None = None
        self._session: RecordingFile | None = None
        self._path: Path | None = None
        self._started_at: float | None = None
        self._stopped_at: float | None = None
        self._error: str | None = None

    # ---- the link side (any thread) --------------------------------------------------------

    def put(self, item: Item, size: int) -> None:
        """Queue one item for the writer; dropped and counted when the queue is full."""
        if not self._accepting:
            return  # not recording: the common case costs one attribute read
        with self._cond:
            if not self._accepting:
                return
            cost = size + ITEM_OVERHEAD_BYTES
            if self._queued_bytes + cost > self.max_queue_bytes:
                self._dropped += 1
                return
            self._queue.append(item)
            self._queued_bytes += cost
            if self._queued_bytes * 4 >= self.max_queue_bytes:
                self._cond.notify()

    def attach(self, link: Link) -> None:
        """Record what this link sends and receives (while recording)."""
        link.subscribe(self.on_event)

    def detach(self, link: Link) -> None:
        """Stop recording this link."""
        link.unsubscribe(self.on_event)

    def on_event(self, event: LinkEvent) -> None:
        """One link event into the queue (the link's threads; never blocks)."""
        kept = item_of(event, self.clock)
        if kept is None or (kept[0][0] == VIDEO and not self.decoded_video):
            return
        self.put(*kept)

    # ---- control ---------------------------------------------------------------------------

    @property
    def recording(self) -> bool:
        """Whether a recording is being written."""
        with self._cond:
            return self._accepting

    @property
    def path(self) -> Path | None:
        """The file of the current (or last) recording."""
        return self._path

    @property
    def error(self) -> str | None:
        """Why the last recording stopped by itself, or None."""
        with self._cond:
            return self._error

    def start(self, path: str | Path, note: str = "") -> None:
        """Open the file and start writing; RecordingError if it cannot be written."""
        target = Path(path)
        with self._control:
            if self._thread is not None and self._thread.is_alive():
                raise RecordingError(f"already recording to {self._path}")
            self._join_finished_thread()
            self._check_free_space(target)
            try:
                session = RecordingFile(
                    self.profile,
                    target,
                    chunk_bytes=self.chunk_bytes,
                    flush_period_s=self.flush_period_s,
                    compression=self.compression,
                    clock=self.clock,
                    note=note,
                )
            except OSError as err:
                raise RecordingError(f"cannot record to {target}: {_describe(err)}") from err
            with self._cond:
                self._queue.clear()
                self._queued_bytes = 0
                self._dropped = 0
                self._error = None
                self._stopping = False
                self._accepting = True
            self._session = session
            self._path = target
            self._started_at = session.mono0
            self._stopped_at = None
            self._thread = threading.Thread(target=self._run, name="ocu-record", daemon=True)
            self._thread.start()
            log.info("recording to %s", target)
            self.put((EVENT, self.clock(), s.EVENT_RECORDING, "started", str(target)), 0)

    def stop(self, timeout_s: float = STOP_TIMEOUT_S) -> RecorderStats:
        """Write what is queued, finish the file (summary and footer) and close it."""
        with self._control:
            thread = self._thread
            if thread is not None:
                self.put((EVENT, self.clock(), s.EVENT_RECORDING, "stopped", "operator"), 0)
                with self._cond:
                    self._accepting = False
                    self._stopping = True
                    self._cond.notify()
                if thread is not threading.current_thread():
                    thread.join(timeout_s)
                    if thread.is_alive():
                        log.error("recorder did not finish within %.1f s", timeout_s)
                self._join_finished_thread()
            return self.stats()

    def stats(self) -> RecorderStats:
        """Counters now."""
        session = self._session
        with self._cond:
            recording = self._accepting
            dropped = self._dropped
            queued = self._queued_bytes
            error = self._error
        start = self._started_at
        end = self._stopped_at if self._stopped_at is not None else self.clock()
        written = session.messages if session is not None else 0
        size = session.file_bytes() if session is not None else 0
        return RecorderStats(
            recording=recording,
            path=self._path,
            elapsed_s=0.0 if start is None else max(end - start, 0.0),
            messages_written=written,
            bytes_written=size,
            dropped=dropped,
            queued_bytes=queued,
            error=error,
        )

    def _join_finished_thread(self) -> None:
        thread = self._thread
        if thread is not None and not thread.is_alive():
            self._thread = None

    def _check_free_space(self, target: Path) -> None:
        if target.exists() and not target.is_file():
            return  # a device or a directory: open() below says what is wrong
        directory = target.parent if str(target.parent) else Path(".")
        try:
            free = shutil.disk_usage(directory).free
        except OSError:
            return  # open() below says what is wrong with the path
        if free < self.min_free_bytes:
            raise RecordingError(
                f"cannot record to {target}: only {free / 1e6:.1f} MB free on its disk "
                f"(at least {self.min_free_bytes / 1e6:.0f} MB needed)"
            )

    # ---- the writer thread -----------------------------------------------------------------

    def _run(self) -> None:
        session = self._session
        assert session is not None
        try:
            while True:
                with self._cond:
                    self._cond.wait_for(
                        lambda: self._stopping or self._queued_bytes * 4 >= self.max_queue_bytes,
                        BATCH_PERIOD_S,
                    )
                    items = self._queue
                    self._queue = deque()
                    self._queued_bytes = 0
                    stopping = self._stopping
                for item in items:
                    session.convert(item, self._dropped)
                session.write_due(None if stopping else self.clock() - REORDER_HOLD_S)
                session.flush_if_due(self.clock())
                if stopping:
                    break
            session.finish()
        except Exception as err:
            self._fail(session, err)
        finally:
            self._stopped_at = self.clock()
            session.close()

    def _fail(self, session: RecordingFile, err: Exception) -> None:
        detail = _describe(err) if isinstance(err, OSError) else f"{type(err).__name__}: {err}"
        message = (
            f"recording to {session.path} stopped: {detail}; the file is readable up to its "
            "last complete chunk"
        )
        if not isinstance(err, OSError):
            log.exception("recorder failed")
        with self._cond:
            self._accepting = False
            self._error = message
            self._queue.clear()
            self._queued_bytes = 0
        log.error("%s", message)
        if self.on_error is not None:
            try:
                self.on_error(message)
            except Exception:
                log.exception("recorder error callback failed")


def _describe(err: OSError) -> str:
    return err.strerror or str(err) or type(err).__name__
