"""The core's side of `ocu.core.remote`: `ModelServer` answers the GUI's `RemoteModel`.

It runs in the control core's process (ocu.core_process): one thread reads the GUI's requests
and answers each under the model's lock; what it sends (answers, forwarded events, the link's
events) goes through the `Sender`'s queue, so no thread of the core ever waits for the GUI.
The messages are those of `ocu.core.remote`'s docstring.
"""

from __future__ import annotations

import logging
import pickle
import socket
import threading
from collections.abc import Callable, Iterable
from typing import Any

from ocu.console.events import Event
from ocu.core.remote import CallbackRef, Path, RemoteError, Sender, receive

log = logging.getLogger("ocu.core")


class _Forward:
    """What a `CallbackRef` becomes in the core: a call sent back to the GUI."""

    def __init__(self, server: ModelServer, token: int) -> None:
        self.server = server
        self.token = token

    def __call__(self, *args: Any, **kwargs: Any) -> None:
        self.server.send(("callback", self.token, args, kwargs))

    def __eq__(self, other: object) -> bool:
        return isinstance(other, _Forward) and other.token == self.token

    def __hash__(self) -> int:
        return hash(self.token)


def event_names(value: object) -> tuple[str, ...]:
    """The Event attributes of an event group (empty for anything else)."""
    attributes = getattr(value, "__dict__", None)
    if not attributes or isinstance(value, type):
        return ()
    return tuple(name for name, item in attributes.items() if isinstance(item, Event))


class ModelServer:
    """Answers a `RemoteModel` from the core's process (module docstring).

    `roots`: the objects the GUI may reach by name ("" is the model); every touch holds
    `lock` (the model's). `touched` is called after each call from the GUI (its sign of
    life); `on_closed` once when the GUI's end closes.
    """

    def __init__(
        self,
        sock: socket.socket,
        roots: dict[str, object],
        lock: threading.RLock,
        *,
        touched: Callable[[], None] | None = None,
        on_closed: Callable[[], None] | None = None,
    ) -> None:
        self.sock = sock
        self.roots = dict(roots)
        self.lock = lock
        self.touched = touched
        self.on_closed = on_closed
        self.sender = Sender(sock, "ocu-core-sender")
        self._forwarders: dict[tuple[Path, str], Callable[..., None]] = {}
        self._callbacks: dict[int, _Forward] = {}
        self.requests = 0
        self.answered: dict[str, tuple[int, int]] = {}  # "path.name" -> (answers, bytes)
        self.closed = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def dropped(self) -> int:
        """Messages to the GUI dropped because it did not read them."""
        return self.sender.dropped

    def add_root(self, name: str, value: object) -> None:
        """Let the GUI reach `value` by `name` too."""
        with self.lock:
            self.roots[name] = value

    def start(self) -> None:
        """Answer requests on a thread of its own."""
        self._thread = threading.Thread(target=self._run, name="ocu-core-server", daemon=True)
        self._thread.start()

    def send(self, message: tuple[Any, ...], *, video: bool = False) -> bool:
        """Send a message to the GUI (any thread, never waits for the GUI)."""
        try:
            return self.sender.send(message, video=video) > 0
        except Exception:  # a value that does not pickle must not break the emitter
            log.exception("could not send %s to the GUI", message[0])
            return False

    def close(self) -> None:
        """Send what is queued and stop answering."""
        self.sender.close()
        self.closed.set()

    # ---- answering ------------------------------------------------------------------------

    def _run(self) -> None:
        try:
            while True:
                message = receive(self.sock)
                if message is None:
                    break
                self.requests += 1
                self._handle(message)
        except Exception:
            log.exception("the core's server stopped")
        finally:
            self.closed.set()
            if self.on_closed is not None:
                self.on_closed()

    def _resolve(self, path: Path) -> object:
        value = self.roots[path[0]]
        for name in path[1:]:
            value = getattr(value, name)
        return value

    def _arguments(self, values: Iterable[Any]) -> list[Any]:
        return [self._callback(v) if isinstance(v, CallbackRef) else v for v in values]

    def _callback(self, ref: CallbackRef) -> _Forward:
        forward = self._callbacks.get(ref.token)
        if forward is None:
            forward = self._callbacks[ref.token] = _Forward(self, ref.token)
        return forward

    def _handle(self, message: tuple[Any, ...]) -> None:
        kind = message[0]
        if kind in ("post", "emit", "listen"):
            try:
                with self.lock:
                    self._act(kind, message)
            except Exception:
                log.exception("the GUI's %s %s.%s failed", kind, message[1], message[2])
            return
        request_id = message[1]
        try:
            with self.lock:
                reply = self._answer(kind, message)
                if kind == "call" and self.touched is not None:
                    self.touched()
        except Exception as error:
            self._send_error(request_id, error)
            return
        try:
            size = self.sender.send(("ok", request_id, *reply))
        except Exception as error:  # the value does not pickle
            path, name = message[2], message[3]
            self._send_error(
                request_id,
                RemoteError(f"{'.'.join((*path, name))} cannot cross to the GUI: {error}"),
            )
            return
        if kind in ("get", "call"):
            # What the GUI asks for, and how much it costs (bench/bench_core.py prints it).
            key = ".".join((*message[2], message[3]))
            count, total = self.answered.get(key, (0, 0))
            self.answered[key] = (count + 1, total + size)
        if not size:
            log.warning("the answer to %s was dropped (the GUI is not reading)", kind)

    def _send_error(self, request_id: int, error: BaseException) -> None:
        try:
            pickle.loads(pickle.dumps(error))
            self.sender.send(("err", request_id, error))
        except Exception:
            self.sender.send(("err", request_id, RemoteError(f"{type(error).__name__}: {error}")))

    def _answer(self, kind: str, message: tuple[Any, ...]) -> tuple[Any, ...]:
        if kind == "get":
            _, _, path, name = message
            owner = self._resolve(path)
            value = getattr(owner, name)
            if getattr(type(value), "guarded", False):
                return ("part", None)
            if getattr(value, "__self__", None) is owner and callable(value):
                return ("method", None)
            names = event_names(value)
            if names:
                return ("events", names)
            return ("value", value)
        if kind == "call":
            _, _, path, name, args, kwargs = message
            method = getattr(self._resolve(path), name)
            result = method(
                *self._arguments(args),
                **dict(zip(kwargs, self._arguments(kwargs.values()), strict=True)),
            )
            return ("value", result)
        if kind == "set":
            _, _, path, name, value = message
            setattr(self._resolve(path), name, value)
            return ("value", None)
        if kind == "ping":
            return ("value", message[2])
        raise RemoteError(f"unknown request {kind!r}")

    def _act(self, kind: str, message: tuple[Any, ...]) -> None:
        if kind == "post":
            _, path, name, args, kwargs = message
            getattr(self._resolve(path), name)(*self._arguments(args), **kwargs)
        elif kind == "emit":
            _, path, name, args, kwargs = message
            getattr(self._resolve(path), name).emit(*args, **kwargs)
        else:  # listen
            _, path, name = message
            key = (path, name)
            if key in self._forwarders:
                return
            event = getattr(self._resolve(path), name)

            def forward(*args: Any, **kwargs: Any) -> None:
                self.send(("event", path, name, args, kwargs))

            event.connect(forward, direct=True)
            self._forwarders[key] = forward
