"""The model's handle across a process boundary: the control core in a process of its own.

`ocu.core.guard.Guarded` is how the GUI thread touches a model that the control thread runs:
attribute reads, method calls, parts (`guarded = True` classes) and event groups, each under
the model's lock. `RemoteModel` is the same interface over a socket pair to another process,
where `ModelServer` (ocu.core.remote_server) answers it under the same lock
(docs/core-process.md):

- a read or a call is one round trip: ("get" | "call" | "set", id, path, name, ...) answered
  by ("ok", id, kind, value) or ("err", id, exception). `kind` says what the attribute is:
  a plain value (returned as it is), a method (a `RemoteMethod` is kept for it), a part (a
  `RemotePart` for it, so `model.arm is model.arm` holds) or an event group (a
  `RemoteEventGroup`, its events by name);
- an exception raised in the core is raised again in the GUI with its type and message (as
  `RemoteError` when it does not pickle);
- a callable passed as an argument (a hook, a callback) stays in the GUI process: the core gets
  a `CallbackRef`, and calling it there calls it in the GUI (later, never with a result);
- events: the first callback connected to a `RemoteEvent` asks the core to forward that
  event; each emit in the core then comes back as ("event", path, name, args, kwargs), in the
  order emitted, and the GUI side calls its callbacks on the dispatching thread (`post`: the
  GUI's inbox). What a call emitted in the core is dispatched before the call returns on
  that thread, as in one process, where the callbacks run inside the call;
- ("post", path, name, args, kwargs) is a call without an answer (key events, the GUI's
  heartbeat); ("emit", ...) emits a model's event from the GUI (a view's message);
- the core also sends ("link", event) for its link's events (ocu.core.remote_link) and
  ("callback", token, args, kwargs).

The control thread never waits for the GUI: what the core sends goes into a queue that a
sender thread writes; past `MAX_QUEUED` messages the newest video frames are dropped first,
then anything else, counted in `ModelServer.dropped`. Each message is a 4-byte big-endian
length and a pickle; both ends are this program, started by it on its own socket pair.
"""

from __future__ import annotations

import contextlib
import itertools
import logging
import pickle
import socket
import struct
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any, Final

log = logging.getLogger("ocu.core")

HEADER: Final = struct.Struct(">I")
MAX_MESSAGE_BYTES: Final = 64 * 1024 * 1024
# A round trip the core did not answer in this long raises (the core is stuck: a core that
# ended is seen at once, its pipe closes). Long: a loaded machine must not make it fire.
CALL_TIMEOUT_S: Final = 10.0
# Messages waiting for the sender thread; the newest video frames go first past it.
MAX_QUEUED: Final = 2000
MAX_QUEUED_VIDEO: Final = 16

Path = tuple[str, ...]


class CoreGoneError(ConnectionError):
    """The control core's process ended (or its pipe closed)."""


class RemoteError(RuntimeError):
    """An exception in the core that could not be sent as it was: its type and message."""


@dataclass(frozen=True)
class CallbackRef:
    """A callable that stays in the GUI process, as the core sees it."""

    token: int


# ---- the wire ------------------------------------------------------------------------------


def pack(message: tuple[Any, ...]) -> bytes:
    """One message as it goes on the socket."""
    body = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
    return HEADER.pack(len(body)) + body


def _read_exactly(sock: socket.socket, size: int) -> bytes | None:
    chunks = bytearray()
    while len(chunks) < size:
        try:
            chunk = sock.recv(size - len(chunks))
        except OSError as error:
            log.warning("the core's pipe (fd %d) failed: %s", sock.fileno(), error)
            return None
        if not chunk:
            return None
        chunks += chunk
    return bytes(chunks)


def receive(sock: socket.socket) -> tuple[Any, ...] | None:
    """The next message (blocking); None when the other end closed."""
    head = _read_exactly(sock, HEADER.size)
    if head is None:
        return None
    (size,) = HEADER.unpack(head)
    if size > MAX_MESSAGE_BYTES:
        raise CoreGoneError(f"a message of {size} bytes on the core's pipe")
    body = _read_exactly(sock, size)
    if body is None:
        return None
    message = pickle.loads(body)
    if not isinstance(message, tuple) or not message or not isinstance(message[0], str):
        raise CoreGoneError(f"not a message on the core's pipe: {type(message).__name__}")
    return message


class Sender:
    """A queue of messages and the thread that writes them (nobody else waits on the socket)."""

    def __init__(self, sock: socket.socket, name: str) -> None:
        self._sock = sock
        self._queue: deque[tuple[bytes, bool]] = deque()
        self._ready = threading.Condition()
        self._closed = False
        self.dropped = 0
        self.sent = 0
        self._video = 0  # video frames queued
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def send(self, message: tuple[Any, ...], *, video: bool = False) -> int:
        """Queue one message (pickled here, so later changes to its values do not show); its
        size in bytes, 0 if it was dropped."""
        data = pack(message)
        with self._ready:
            if self._closed:
                return False
            queue = self._queue
            if video and self._video >= MAX_QUEUED_VIDEO:
                self.dropped += 1
                return 0
            if len(queue) >= MAX_QUEUED:
                self.dropped += 1
                return 0
            queue.append((data, video))
            self._video += video
            self._ready.notify()
        return len(data)

    def close(self) -> None:
        """Send what is queued, then stop (the socket stays open)."""
        with self._ready:
            self._closed = True
            self._ready.notify()
        if self._thread is not threading.current_thread():
            self._thread.join(2.0)

    def _run(self) -> None:
        while True:
            with self._ready:
                while not self._queue and not self._closed:
                    self._ready.wait()
                if not self._queue:
                    return
                batch = list(self._queue)
                self._queue.clear()
                self._video = 0
            try:
                self._sock.sendall(b"".join(data for data, _ in batch))
            except OSError:
                with self._ready:
                    self._closed = True
                return
            self.sent += len(batch)


# ---- the GUI's side ------------------------------------------------------------------------


class _Pending:
    __slots__ = ("done", "reply")

    def __init__(self) -> None:
        self.done = threading.Event()
        self.reply: tuple[Any, ...] | None = None


class CoreConnection:
    """The GUI's end of the pipe: round trips, and what the core sends unasked.

    `post(fn)` hands a call to the dispatching thread (the GUI's: its inbox); events and
    callbacks are dispatched there. `on_link(event)` takes the link's events on the reader
    thread. `on_closed()` is called (on the reader thread) once the core is gone.
    """

    def __init__(
        self,
        sock: socket.socket,
        *,
        post: Callable[[Callable[[], None]], None] | None = None,
        on_link: Callable[[Any], None] | None = None,
        on_closed: Callable[[], None] | None = None,
        timeout_s: float = CALL_TIMEOUT_S,
    ) -> None:
        self.sock = sock
        self.post = post
        self.on_link = on_link
        self.on_closed = on_closed
        self.timeout_s = timeout_s
        self.dispatch_thread = threading.get_ident()
        self._write_lock = threading.Lock()
        self._ids = itertools.count(1)
        self._pending: dict[int, _Pending] = {}
        self._pending_lock = threading.Lock()
        self._inbox: deque[tuple[Any, ...]] = deque()
        self._inbox_lock = threading.Lock()
        self._drain_posted = False
        self._listeners: dict[tuple[Path, str], list[Callable[..., None]]] = {}
        self._callbacks: dict[int, Callable[..., Any]] = {}
        self._tokens: dict[Callable[..., Any], int] = {}
        self.last_values: dict[tuple[Path, str], Any] = {}
        self.closed = threading.Event()
        # Once the core is gone, reads and calls go to these, by root ("" the model: one of
        # the GUI's own, halted, commanding nothing), so the views still have answers.
        self.fallbacks: dict[str, object] = {}
        self.round_trips = 0
        self.round_trip_s = 0.0
        self._reader = threading.Thread(target=self._read, name="ocu-core-reader", daemon=True)
        self._reader.start()

    # ---- sending --------------------------------------------------------------------------

    def _write(self, message: tuple[Any, ...]) -> None:
        data = pack(message)
        with self._write_lock:
            try:
                self.sock.sendall(data)
            except OSError as error:
                raise CoreGoneError(f"the control core is gone ({error})") from error

    def request(self, kind: str, path: Path, name: str, *rest: Any) -> tuple[str, Any]:
        """One round trip; (kind, value) of the answer. Raises what the core raised."""
        if self.closed.is_set():
            raise CoreGoneError("the control core is gone")
        request_id = next(self._ids)
        pending = _Pending()
        with self._pending_lock:
            self._pending[request_id] = pending
        asked = time.perf_counter()
        try:
            self._write((kind, request_id, path, name, *rest))
            if not pending.done.wait(self.timeout_s):
                raise CoreGoneError(
                    f"the control core did not answer {'.'.join((*path, name))} in "
                    f"{self.timeout_s:.0f} s"
                )
        finally:
            with self._pending_lock:
                self._pending.pop(request_id, None)
        self.round_trips += 1
        self.round_trip_s += time.perf_counter() - asked
        reply = pending.reply
        if reply is None:
            raise CoreGoneError("the control core is gone")
        # What the core emitted before it answered is dispatched before the caller goes on.
        if threading.get_ident() == self.dispatch_thread:
            self.drain()
        if reply[0] == "err":
            raise reply[2]
        return reply[2], reply[3]

    def tell(self, kind: str, path: Path, name: str, *rest: Any) -> None:
        """A message without an answer (in order with the round trips)."""
        if self.closed.is_set():
            return
        try:
            self._write((kind, path, name, *rest))
        except CoreGoneError:
            log.debug("%s %s.%s: the core is gone", kind, path, name)

    def arguments(self, values: Iterable[Any]) -> list[Any]:
        """Callables become CallbackRefs (the same callable: the same token)."""
        out: list[Any] = []
        for value in values:
            if callable(value) and not isinstance(value, type):
                token = self._tokens.get(value)
                if token is None:
                    token = self._tokens[value] = len(self._tokens) + 1
                    self._callbacks[token] = value
                out.append(CallbackRef(token))
            else:
                out.append(value)
        return out

    def listen(self, path: Path, name: str, callback: Callable[..., None]) -> None:
        """Call `callback` with each emit of the core's event (asked for on the first)."""
        callbacks = self._listeners.setdefault((path, name), [])
        if not callbacks:
            self.tell("listen", path, name)
        callbacks.append(callback)

    def unlisten(self, path: Path, name: str, callback: Callable[..., None]) -> None:
        """Stop calling `callback`."""
        callbacks = self._listeners.get((path, name), [])
        for index, connected in enumerate(callbacks):
            if connected == callback:
                del callbacks[index]
                return

    # ---- receiving ------------------------------------------------------------------------

    def _read(self) -> None:
        try:
            while True:
                message = receive(self.sock)
                if message is None:
                    break
                kind = message[0]
                if kind in ("ok", "err"):
                    with self._pending_lock:
                        pending = self._pending.get(message[1])
                    if pending is not None:
                        pending.reply = message
                        pending.done.set()
                elif kind == "link":
                    if self.on_link is not None:
                        try:
                            self.on_link(message[1])
                        except Exception:
                            log.exception("a link event from the core failed")
                else:
                    self._queue(message)
        except Exception:
            log.exception("the pipe from the core broke")
        finally:
            self.closed.set()
            with self._pending_lock:
                waiting = list(self._pending.values())
            for pending in waiting:
                pending.done.set()
            if self.on_closed is not None:
                self.on_closed()

    def _queue(self, message: tuple[Any, ...]) -> None:
        with self._inbox_lock:
            self._inbox.append(message)
            if self._drain_posted:
                return
            self._drain_posted = True
        if self.post is None:
            self.drain()
        else:
            self.post(self.drain)

    def drain(self) -> None:
        """Dispatch what the core sent so far (the dispatching thread)."""
        while True:
            with self._inbox_lock:
                if not self._inbox:
                    self._drain_posted = False
                    return
                message = self._inbox.popleft()
            self._dispatch(message)

    def _dispatch(self, message: tuple[Any, ...]) -> None:
        if message[0] == "event":
            _, path, name, args, kwargs = message
            callbacks = list(self._listeners.get((path, name), ()))
        else:  # callback
            _, token, args, kwargs = message
            callback = self._callbacks.get(token)
            callbacks = [] if callback is None else [callback]
        for callback in callbacks:
            try:
                callback(*args, **kwargs)
            except Exception:
                log.exception("callback %r of the core's %s failed", callback, message[0])

    def local(self, path: Path) -> object:
        """The fallback's object at `path` (the core is gone); CoreGoneError if none."""
        value = self.fallbacks.get(path[0])
        if value is None:
            raise CoreGoneError(f"the control core is gone: no {'.'.join(path)}")
        for name in path[1:]:
            value = getattr(value, name)
        return value

    def inject(self, path: Path, name: str, *args: Any) -> None:
        """Dispatch an event here as if the core had emitted it (the core is gone)."""
        self._queue(("event", path, name, args, {}))

    def close(self, timeout_s: float = 5.0) -> None:
        """Close the pipe (the core halts the robot and ends); the reader thread has ended
        when this returns (unless it is the caller)."""
        self.closed.set()
        with contextlib.suppress(OSError):
            self.sock.shutdown(socket.SHUT_RDWR)
        if self._reader is not threading.current_thread():
            self._reader.join(timeout_s)
        self.sock.close()


class RemoteEvent:
    """A model's event in the core, as the GUI connects to it (`ocu.console.events.Event`)."""

    def __init__(self, connection: CoreConnection, path: Path, name: str) -> None:
        self._connection = connection
        self._path = path
        self._name = name

    def connect(self, callback: Callable[..., None], *, direct: bool = False) -> None:
        """Call `callback` on every emit in the core (on the dispatching thread)."""
        del direct  # across processes every callback is handed over
        self._connection.listen(self._path, self._name, callback)

    def disconnect(self, callback: Callable[..., None]) -> None:
        """Stop calling `callback`."""
        self._connection.unlisten(self._path, self._name, callback)

    def emit(self, *args: Any, **kwargs: Any) -> None:
        """Emit the event in the core (its callbacks there, and these here, are called)."""
        self._connection.tell("emit", self._path, self._name, args, kwargs)


class RemoteEventGroup:
    """An event group of the core's model: its events by name."""

    def __init__(self, connection: CoreConnection, path: Path, names: Iterable[str]) -> None:
        for name in names:
            object.__setattr__(self, name, RemoteEvent(connection, path, name))


class RemoteMethod:
    """A method of an object in the core: each call is a round trip."""

    def __init__(self, connection: CoreConnection, path: Path, name: str) -> None:
        self._connection = connection
        self._path = path
        self.__name__ = name

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        connection = self._connection
        if connection.closed.is_set():
            return getattr(connection.local(self._path), self.__name__)(*args, **kwargs)
        values = connection.arguments(kwargs.values())
        try:
            _, value = connection.request(
                "call",
                self._path,
                self.__name__,
                tuple(connection.arguments(args)),
                dict(zip(kwargs, values, strict=True)),
            )
        except CoreGoneError:
            if self._path[0] not in connection.fallbacks:
                raise
            return getattr(connection.local(self._path), self.__name__)(*args, **kwargs)
        return value

    def post(self, *args: Any, **kwargs: Any) -> None:
        """Call it without waiting for the answer (what it raises is logged in the core)."""
        self._connection.tell("post", self._path, self.__name__, args, kwargs)


class RemotePart:
    """An object in the core reached by a path of attribute names (the model, its parts)."""

    def __init__(self, connection: CoreConnection, path: Path) -> None:
        object.__setattr__(self, "_connection", connection)
        object.__setattr__(self, "_path", path)
        object.__setattr__(self, "_handles", {})

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__"):
            raise AttributeError(name)
        handles = self._handles
        handle = handles.get(name)
        if handle is not None:
            return handle
        connection: CoreConnection = self._connection
        key = (self._path, name)
        if connection.closed.is_set():
            if self._path[0] not in connection.fallbacks and key in connection.last_values:
                return connection.last_values[key]
            return getattr(connection.local(self._path), name)
        try:
            kind, value = connection.request("get", self._path, name)
        except CoreGoneError:
            if self._path[0] not in connection.fallbacks:
                raise
            return getattr(connection.local(self._path), name)
        if kind == "value":
            connection.last_values[key] = value
            return value
        path = (*self._path, name)
        if kind == "part":
            handle = RemotePart(connection, path)
        elif kind == "method":
            handle = RemoteMethod(connection, self._path, name)
        else:
            handle = RemoteEventGroup(connection, path, value)
        handles[name] = handle
        return handle

    def __setattr__(self, name: str, value: object) -> None:
        connection: CoreConnection = self._connection
        if connection.closed.is_set():
            setattr(connection.local(self._path), name, value)
        else:
            connection.request("set", self._path, name, value)

    def __repr__(self) -> str:
        return f"RemotePart({'.'.join(self._path) or 'model'})"


def remote_root(connection: CoreConnection, name: str = "") -> Any:
    """The GUI's handle on a root of the core's server ("" is the model)."""
    return RemotePart(connection, (name,))
