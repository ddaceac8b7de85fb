"""The control core in a process of its own (docs/core-process.md).

`CoreProcess` starts `python -m ocu.core_process FD` with one end of a socket pair and sends it
a `CoreSpec`: the robot's profile, the hardware plug-in to connect (ocu.hardware.registry:
"engineer" at "HOST:PORT", "ur", "xarm" ...), the model's settings and the control rate. The
child builds the `ConsoleModel` and the `ControllerManager` (ocu.core.manager) and answers the
GUI's `RemoteModel` (ocu.core.remote) under the model's lock:

- "" is the model; "@core" is the `Core` below (connect and disconnect the hardware, the
  GUI's heartbeat, the control thread's timing); "@link" the current link (what the GUI's
  `RemoteLink` asks); each of `CoreSpec.parts` ("NAME=module:function", the function called
  with the `Core`) is a root of its own: the X key reader ("keys") is one;
- while connected, every event of the link except the raw datagrams goes to the GUI (the
  video's compressed frames are decoded there);
- the GUI's end closes (the window closed, the GUI process died): the model is halted, the
  hardware shut down (zeros last) and the process ends. The GUI silent but alive: the
  manager's "GUI silent" lock, fed by the GUI's heartbeat posts;
- the core gone: the robot stops by itself (its link's watchdog), the GUI shows it.

It runs at `CoreSpec.nice` (-15 by default, above the -10 `ocu` asks for itself; where the
user may raise priority) so that neither CPU-bound processes beside the console nor the GUI's
own paints delay a key.
"""

from __future__ import annotations

import importlib
import logging
import os
import signal
import socket
import subprocess
import sys
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ocu.console.model import ConsoleModel
from ocu.core.hardware import HardwareComponent
from ocu.core.manager import DEFAULT_RATE_HZ, ControllerManager, ControlTiming
from ocu.core.remote import (
    CALL_TIMEOUT_S,
    CoreConnection,
    CoreGoneError,
    pack,
    receive,
    remote_root,
)
from ocu.core.remote_link import forward_link_events
from ocu.core.remote_server import ModelServer
from ocu.profile import RobotProfile

log = logging.getLogger("ocu.core")

# The child's priority, where the user may ask for it: above the desktop's CPU-bound jobs, and
# above the GUI's process (nice -10, ocu.priority): when the CPU is short, a paint in the GUI
# never delays the core's threads (a key, a control cycle, the command to the robot).
CORE_NICE = -15
START_TIMEOUT_S = 20.0
# A real-time policy (SCHED_RR) where the user may have one (root, CAP_SYS_NICE, an
# RLIMIT_RTPRIO allowance): every thread of the core then runs as soon as it wakes, ahead of
# any CPU-bound job, and a thread holding the core's GIL is never preempted by one (with the
# nice value alone, a hog beside the console still delayed a key by up to 8 ms at the p99,
# as much as a process doing nothing but reading the key: bench_core --x11 --floor). The
# core needs about a fifth of a core; the kernel keeps 5 % of each second for the others
# whatever it does.
REALTIME_PRIORITY = 10
# The core's threads share its GIL (the link's receiver reassembling video, the GUI's server,
# the control thread, the key reader): at Python's default 5 ms switch interval a key waits
# up to that long behind the video's reassembly; the window's process uses the same 1 ms.
GIL_SWITCH_INTERVAL_S = 0.001
STOP_TIMEOUT_S = 5.0


class CoreProcessError(RuntimeError):
    """The core process could not be started or did not answer."""


@dataclass(frozen=True)
class CoreSpec:
    """What the core process builds (it pickles: the child gets it on its pipe)."""

    profile: RobotProfile
    hardware: str = "engineer"  # a plug-in of ocu.hardware.registry
    target: str = ""
    options: dict[str, Any] = field(default_factory=dict)
    fine_factor: float = 0.25
    arm_poses_path: Path | None = None
    control_hz: float = DEFAULT_RATE_HZ
    gui_timeout_s: float | None = None
    parts: tuple[str, ...] = ()  # "NAME=module:function", called with the Core
    key_map: Any = None  # ocu.hotkeys.KeyMap: what the X key reader acts on
    pad_mapping: Any = None  # ocu.gamepad.mapping.PadMapping: the "pad" part's
    pad_calibrations: Path | None = None  # the pads' calibration file
    nice: int = CORE_NICE
    realtime: bool = True  # SCHED_RR where allowed (REALTIME_PRIORITY)
    log_level: int = logging.INFO


def load_function(text: str) -> Callable[..., Any]:
    """ "module:function" to the function."""
    module, _, name = text.partition(":")
    if not module or not name:
        raise CoreProcessError(f"not module:function: {text!r}")
    function = getattr(importlib.import_module(module), name, None)
    if not callable(function):
        raise CoreProcessError(f"{text!r} is not a function")
    return function  # type: ignore[no-any-return]


class Core:
    """The child's side: the model, its control thread, the hardware and the GUI's server."""

    def __init__(self, spec: CoreSpec, sock: socket.socket) -> None:
        self.spec = spec
        self.model = ConsoleModel(
            spec.profile, fine_factor=spec.fine_factor, arm_poses_path=spec.arm_poses_path
        )
        self.lock = threading.RLock()
        alive = spec.profile.link.gui_alive_timeout_s
        self.manager = ControllerManager(
            self.model,
            self.lock,
            rate_hz=spec.control_hz,
            alive_timeout_s=alive,
            gui_timeout_s=spec.gui_timeout_s if spec.gui_timeout_s is not None else alive,
        )
        self.hardware: HardwareComponent | None = None
        self.gone = threading.Event()
        self.server = ModelServer(
            sock,
            {"": self.model, "@core": self},
            self.lock,
            touched=self.manager.gui_alive,
            on_closed=self.gone.set,
        )
        self._unsubscribe: Callable[[], None] | None = None
        self.parts: dict[str, object] = {}
        for text in spec.parts:
            name, _, where = text.partition("=")
            part = load_function(where)(self)
            self.parts[name] = part
            self.server.add_root(name, part)

    # ---- what the GUI calls (under the model's lock) ----------------------------------------

    def prepare(self) -> str:
        """Build the hardware and read and write it from now on, not started yet (as a link
        is made before it starts: its rate, its listeners); its description."""
        self.disconnect()
        from ocu.hardware.registry import HARDWARE

        spec = self.spec
        hardware = HARDWARE.create(spec.hardware, spec.profile, spec.target, **spec.options)
        self.hardware = hardware
        self.manager.attach(hardware)  # subscribed before any datagram flows
        self._unsubscribe = forward_link_events(hardware.link, self.server.send)
        self.server.add_root("@link", hardware.link)
        return hardware.description

    def connect(self) -> str:
        """Start the hardware (prepared first if it was not); its description."""
        if self.hardware is None:
            self.prepare()
        assert self.hardware is not None
        self.hardware.start()
        return self.hardware.description

    def disconnect(self) -> None:
        """Stop reading and writing the hardware; shut it down (zeros last); idempotent."""
        hardware, self.hardware = self.hardware, None
        if hardware is None:
            return
        self.manager.detach()
        hardware.shutdown()
        if self._unsubscribe is not None:
            self._unsubscribe()
            self._unsubscribe = None
        hardware.feed.close()

    def gui_alive(self) -> None:
        """The GUI thread's heartbeat."""
        self.manager.gui_alive()

    def timing(self) -> ControlTiming:
        """The control thread's timing."""
        return self.manager.timing()

    def answered(self, top: int = 12) -> list[tuple[str, int, int]]:
        """What the GUI asked most, by bytes: ("path.name", answers, bytes)."""
        rows = [(key, count, size) for key, (count, size) in self.server.answered.items()]
        return sorted(rows, key=lambda row: -row[2])[:top]

    def ping(self, value: object = None) -> object:
        """A round trip (tests and benchmarks)."""
        return value

    def pid(self) -> int:
        """This process's id."""
        return os.getpid()

    # ---- life -----------------------------------------------------------------------------

    def run(self) -> None:
        """Serve until the GUI's end closes (or SIGTERM), then halt and shut down."""
        self.manager.gui_alive()
        self.manager.start()
        self.server.start()
        self.gone.wait()
        self.stop("the console's window is gone")

    def stop(self, reason: str) -> None:
        """Halt the model, stop the parts and the control thread, the zeros last."""
        log.info("control core stopping: %s", reason)
        with self.lock:
            self.model.halt(reason)
        for part in reversed(self.parts.values()):
            stop = getattr(part, "stop", None) or getattr(part, "close", None)
            if callable(stop):
                stop()
        self.manager.stop()
        with self.lock:
            self.disconnect()
        self.server.close()


class CoreProcess:
    """The GUI's side: starts the child, hands out its model (`model`), stops it.

    `post(fn)` hands a call to the GUI thread (events and callbacks are dispatched there);
    `on_closed()` is called once if the core ends on its own.
    """

    def __init__(
        self,
        spec: CoreSpec,
        *,
        post: Callable[[Callable[[], None]], None] | None = None,
        on_closed: Callable[[], None] | None = None,
        timeout_s: float = START_TIMEOUT_S,
    ) -> None:
        self.spec = spec
        ours, theirs = socket.socketpair()
        # Blocking, whatever socket.setdefaulttimeout() says in this process (rospy sets one):
        # with a timeout the fds are non-blocking, and the child inherits that flag.
        ours.settimeout(None)
        theirs.settimeout(None)
        try:
            self.process = subprocess.Popen(
                [sys.executable, "-m", "ocu.core_process", str(theirs.fileno())],
                pass_fds=(theirs.fileno(),),
            )
        finally:
            theirs.close()
        ours.sendall(pack(("spec", spec)))
        self._stopping = False
        self._on_closed = on_closed
        self.connection = CoreConnection(
            ours, post=post, on_closed=self._closed, timeout_s=timeout_s
        )
        self.model: Any = remote_root(self.connection)
        self.core: Any = remote_root(self.connection, "@core")
        try:
            self.pid = int(self.core.pid())  # the first answer: the core is built
        except CoreGoneError as error:
            code = self.stop()
            raise CoreProcessError(
                f"the control core did not start: {error} (exit code {code}; its error above)"
            ) from error
        self.connection.timeout_s = min(timeout_s, CALL_TIMEOUT_S)

    def part(self, name: str) -> Any:
        """The GUI's handle on one of the spec's parts."""
        return remote_root(self.connection, name)

    @property
    def alive(self) -> bool:
        """Whether the child still runs and answers."""
        return self.process.poll() is None and not self.connection.closed.is_set()

    def _closed(self) -> None:
        if not self._stopping and self._on_closed is not None:
            self._on_closed()

    def stop(self, timeout_s: float = STOP_TIMEOUT_S) -> int | None:
        """Close the pipe (the core halts, zeros last, and ends); its exit code."""
        self._stopping = True
        self.connection.close()
        try:
            return self.process.wait(timeout_s)
        except subprocess.TimeoutExpired:
            log.warning("the control core did not end in %.0f s: killed", timeout_s)
            self.process.kill()
            return self.process.wait(timeout_s)


def child_main(fd: int) -> int:
    """The child process: read the spec, build the core, serve until the GUI's end closes."""
    sock = socket.socket(fileno=fd)
    sock.settimeout(None)  # blocking (the parent's default timeout may have made it not)
    message = receive(sock)
    if message is None or message[0] != "spec":
        return 2
    spec: CoreSpec = message[1]
    logging.basicConfig(level=spec.log_level, format="%(asctime)s core %(name)s %(message)s")
    if spec.nice < os.getpriority(os.PRIO_PROCESS, 0):
        try:
            os.setpriority(os.PRIO_PROCESS, 0, spec.nice)
        except OSError:
            log.info("control core: priority not raised to nice %d (not allowed)", spec.nice)
    if spec.realtime:
        # Before any thread starts: each inherits the policy of the thread that starts it.
        try:
            os.sched_setscheduler(0, os.SCHED_RR, os.sched_param(REALTIME_PRIORITY))
        except OSError:
            log.info("control core: no real-time scheduling here (not allowed)")
    sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)
    policy = "SCHED_RR" if os.sched_getscheduler(0) == os.SCHED_RR else "SCHED_OTHER"
    log.info(
        "control core: a process of its own (pid %d, %s, nice %d, hardware %r)",
        os.getpid(), policy, os.getpriority(os.PRIO_PROCESS, 0), spec.hardware,
    )  # fmt: skip
    core = Core(spec, sock)
    signal.signal(signal.SIGTERM, lambda *_: core.gone.set())
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl+C in the terminal is the GUI's
    core.run()
    return 0


if __name__ == "__main__":
    sys.exit(child_main(int(sys.argv[1])))
