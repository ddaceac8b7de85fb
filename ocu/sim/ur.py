"""A Universal Robots controller simulator over real TCP sockets (docs/ur.md "The simulator").

Three ports, as a controller has them (30001 primary, 30002 secondary, 30003 realtime; any
three given, 0 = a free one): on connecting, the primary and secondary clients get the version
message, then robot state (robot mode, joint and masterboard data) at the profile's
`secondary_hz`; realtime clients get one packet of the controller version's layout per control
tick (125 Hz CB3, 500 Hz e-Series). Every port takes URScript lines: speedj, stopj, servoj,
movej (ocu.protocol.ur.parse_script_line); anything else is refused, counted and logged, and
the streams go on. A new script replaces the running one at once, as on a controller.

The arm: joint speeds change at most at the command's acceleration (capped by the profile's);
speedj's `t` runs out -> the arm decelerates to rest at the command's `a` (the robot-side
watchdog); a joint reaching its limit stops the arm at once in a protective stop (safety mode
3, robot mode data `protective_stopped`) that refuses motion until `unlock_protective_stop()`.

Faults (like ocu.sim.faults for the Engineer): `latency_ms` delays every byte each way,
`mute` sends nothing while the connections stay open, `cut()` drops every connection and
refuses new ones until `restore()`, `drop_connections()` drops them once.
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import logging
import math
import selectors
import signal
import socket
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from types import FrameType

from ocu.profile.keys import ProfileError
from ocu.profile.ur import UrArmProfile, load_ur_profile, shipped_ur_profiles
from ocu.protocol.ur import (
    JOINTS,
    JointData,
    JointState,
    MasterboardData,
    RobotMode,
    RobotModeData,
    RobotState,
    SafetyMode,
    UrProtocolError,
    Vector6,
    VersionMessage,
    parse_script_line,
    realtime_size,
    realtime_state,
)
from ocu.sim.ur_arm import UrArm, tcp_pose, vector6

log = logging.getLogger("ocu.sim.ur")

PRIMARY, SECONDARY, REALTIME = "primary", "secondary", "realtime"
PORT_KINDS = (PRIMARY, SECONDARY, REALTIME)
DEFAULT_PORTS = (30001, 30002, 30003)
#: A URScript line longer than this without a newline is garbage: dropped and counted.
MAX_LINE = 4096
#: A client that lets this much output pile up is too slow to be a client: dropped.
MAX_PENDING_OUT = 1 << 20
#: After a stall the loop catches up at most this much simulated time, then skips ahead.
MAX_CATCH_UP_S = 0.1
SETTLED_RAD = 1e-5


# ---- the server ------------------------------------------------------------------------------


@dataclass
class _Client:
    sock: socket.socket
    kind: str
    address: tuple[str, int]
    inbox: bytearray = field(default_factory=bytearray)
    outbox: bytearray = field(default_factory=bytearray)


@dataclass(frozen=True)
class UrSimSnapshot:
    """What the simulator's arm and server are doing, for tests and benchmarks."""

    time_s: float
    q: Vector6
    qd: Vector6
    robot_mode: RobotMode
    safety_mode: SafetyMode
    protective_stopped: bool
    program: str | None
    accepted: int
    refused: int
    #: Controller time (s) at which the last accepted command took effect (nan: none yet).
    last_command_s: float
    clients: dict[str, int]
    realtime_sent: int
    dropped_clients: int
    #: The name of the last accepted URScript command (None: none yet).
    last_command: str | None = None


class UrSimulator:
    """The controller: three listening ports, the arm, faults; start() / stop()."""

    def __init__(
        self,
        profile: UrArmProfile,
        *,
        host: str = "127.0.0.1",
        ports: Sequence[int] = DEFAULT_PORTS,
        controller_version: tuple[int, int, int] | None = None,
        latency_ms: float = 0.0,
        initial_q: Sequence[float] | None = None,
    ) -> None:
        if len(ports) != 3:
            raise ValueError("ports: primary, secondary and realtime, three of them")
        if not (math.isfinite(latency_ms) and latency_ms >= 0):
            raise ValueError(f"latency_ms must be a finite number >= 0, got {latency_ms!r}")
        self.profile = profile
        self.version = controller_version or profile.controller_version
        self.realtime_size = realtime_size(self.version[:2])
        self.period_s = 1.0 / profile.realtime_hz
        self._secondary_every = max(1, round(profile.realtime_hz / profile.secondary_hz))
        self.host = host
        self._requested_ports = tuple(ports)
        self.arm = UrArm(profile, initial_q)
        self._lock = threading.Lock()
        self._latency_s = latency_ms / 1000.0
        self._mute = False
        self._cut = False
        self._drop_requested = False
        self._selector = selectors.DefaultSelector()
        self._listeners: dict[str, socket.socket] = {}
        self._clients: dict[int, _Client] = {}
        self._incoming: collections.deque[tuple[float, bytes]] = collections.deque()
        self._outgoing: collections.deque[tuple[float, _Client, bytes]] = collections.deque()
        self._thread: threading.Thread | None = None
        self._stopping = threading.Event()
        self._wake_r, self._wake_w = socket.socketpair()
        self._ticks = 0
        self._start_s = 0.0
        self.accepted = 0
        self.refused = 0
        self.last_command_s = math.nan
        self.last_command: str | None = None
        self.realtime_sent = 0
        self.dropped_clients = 0
        self.ports: dict[str, int] = {}

    # ---- life ----------------------------------------------------------------------------------

    def start(self) -> None:
        """Listen on the three ports and start the controller loop."""
        for kind, port in zip(PORT_KINDS, self._requested_ports, strict=True):
            listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                listener.bind((self.host, port))
            except OSError:
                listener.close()
                self._close_listeners()
                raise
            listener.listen(8)
            listener.setblocking(False)
            self._listeners[kind] = listener
            self.ports[kind] = listener.getsockname()[1]
            self._selector.register(listener, selectors.EVENT_READ, kind)
        self._wake_r.setblocking(False)
        self._selector.register(self._wake_r, selectors.EVENT_READ, "wake")
        self._start_s = time.monotonic()
        self._thread = threading.Thread(target=self._loop, name="ur-sim", daemon=True)
        self._thread.start()
        log.info(
            "UR simulator %s (controller %s) on %s ports %s",
            self.profile.name,
            ".".join(map(str, self.version)),
            self.host,
            self.ports,
        )

    def stop(self) -> None:
        """Stop the loop and close every socket; idempotent."""
        self._stopping.set()
        self._wake()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        for client in list(self._clients.values()):
            self._close(client, count=False)
        self._close_listeners()
        for sock in (self._wake_r, self._wake_w):
            sock.close()
        self._selector.close()

    def __enter__(self) -> UrSimulator:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _close_listeners(self) -> None:
        for listener in self._listeners.values():
            with contextlib.suppress(KeyError, ValueError):
                self._selector.unregister(listener)
            listener.close()
        self._listeners.clear()

    # ---- faults and controls (any thread) ------------------------------------------------------

    def set_latency_ms(self, latency_ms: float) -> None:
        """Delay every byte each way by this much."""
        if not (math.isfinite(latency_ms) and latency_ms >= 0):
            raise ValueError(f"latency_ms must be a finite number >= 0, got {latency_ms!r}")
        with self._lock:
            self._latency_s = latency_ms / 1000.0

    def set_mute(self, mute: bool) -> None:
        """Send nothing (True) while the connections stay open, or speak again (False)."""
        with self._lock:
            self._mute = mute

    def cut(self) -> None:
        """Drop every connection and refuse new ones until restore()."""
        with self._lock:
            self._cut = True
            self._drop_requested = True
        self._wake()

    def restore(self) -> None:
        """Accept connections again after cut()."""
        with self._lock:
            self._cut = False

    def drop_connections(self) -> None:
        """Drop every connection once (the controller closes them); new ones are accepted."""
        with self._lock:
            self._drop_requested = True
        self._wake()

    def unlock_protective_stop(self) -> None:
        """Clear a protective stop (the dashboard server's command on a controller)."""
        with self._lock:
            self.arm.unlock_protective_stop()

    def emergency_stop(self, pressed: bool = True) -> None:
        """Press (True) or release (False) the robot's emergency stop."""
        with self._lock:
            self.arm.emergency_stopped = pressed
            if pressed:
                self.arm.program = None
                self.arm.qd = [0.0] * JOINTS

    def snapshot(self) -> UrSimSnapshot:
        """The arm's state and the server's counters now."""
        with self._lock:
            arm = self.arm
            counts = collections.Counter(c.kind for c in self._clients.values())
            return UrSimSnapshot(
                time_s=self._ticks * self.period_s,
                q=vector6(arm.q),
                qd=vector6(arm.qd),
                robot_mode=RobotMode.RUNNING,
                safety_mode=arm.safety_mode,
                protective_stopped=arm.protective_stopped,
                program=arm.program.command.name if arm.program else None,
                accepted=self.accepted,
                refused=self.refused,
                last_command_s=self.last_command_s,
                clients={kind: counts.get(kind, 0) for kind in PORT_KINDS},
                realtime_sent=self.realtime_sent,
                dropped_clients=self.dropped_clients,
                last_command=self.last_command,
            )

    def _wake(self) -> None:
        with contextlib.suppress(OSError):
            self._wake_w.send(b"\x00")

    # ---- the loop ------------------------------------------------------------------------------

    def _loop(self) -> None:
        next_tick = time.monotonic()
        while not self._stopping.is_set():
            now = time.monotonic()
            due = [next_tick]
            if self._incoming:
                due.append(self._incoming[0][0])
            if self._outgoing:
                due.append(self._outgoing[0][0])
            timeout = max(0.0, min(due) - now)
            for key, _ in self._selector.select(timeout):
                self._on_ready(key.data, key.fileobj)
            with self._lock:
                drop, self._drop_requested = self._drop_requested, False
            if drop:
                for client in list(self._clients.values()):
                    self._close(client, count=False)
            now = time.monotonic()
            self._run_due_commands(now)
            if now - next_tick > MAX_CATCH_UP_S:
                next_tick = now
            while now >= next_tick:
                self._tick()
                next_tick += self.period_s
            self._flush_due(now)
            self._flush_pending()

    def _on_ready(self, data: object, sock: object) -> None:
        if data == "wake":
            with contextlib.suppress(OSError):
                self._wake_r.recv(4096)
        elif data in PORT_KINDS:
            assert isinstance(sock, socket.socket)
            self._accept(str(data), sock)
        elif isinstance(data, _Client):
            self._read(data)

    def _accept(self, kind: str, listener: socket.socket) -> None:
        try:
            sock, address = listener.accept()
        except OSError:
            return
        with self._lock:
            cut = self._cut
        if cut:
            sock.close()
            return
        sock.setblocking(False)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        client = _Client(sock, kind, address)
        with self._lock:
            self._clients[sock.fileno()] = client
        self._selector.register(sock, selectors.EVENT_READ, client)
        log.info("%s client %s:%d connected", kind, *address[:2])
        # The secondary port sends the version message from 3.1 on (seed 004).
        if kind == PRIMARY or (kind == SECONDARY and self.version >= (3, 1, 0)):
            self._send(client, self._version_message())

    def _read(self, client: _Client) -> None:
        try:
            data = client.sock.recv(65536)
        except BlockingIOError:
            return
        except OSError:
            data = b""
        if not data:
            self._close(client, count=False)
            return
        with self._lock:
            latency = self._latency_s
        # Lines are cut on arrival and run when the latency has passed.
        client.inbox += data
        *lines, rest = client.inbox.split(b"\n")
        client.inbox = bytearray(rest)
        if len(client.inbox) > MAX_LINE:
            client.inbox.clear()
            self._refuse(f"a {client.kind} line over {MAX_LINE} bytes without a newline")
        due = time.monotonic() + latency
        for line in lines:
            self._incoming.append((due, bytes(line)))

    def _run_due_commands(self, now: float) -> None:
        while self._incoming and self._incoming[0][0] <= now:
            _, line = self._incoming.popleft()
            text = line.strip()
            if not text:
                continue
            try:
                command = parse_script_line(text.decode("ascii"))
            except (UnicodeDecodeError, UrProtocolError) as err:
                self._refuse(str(err))
                continue
            with self._lock:
                # The arm runs on controller time: a command takes effect at the next cycle.
                effective_s = (self._ticks + 1) * self.period_s
                reason = self.arm.run(command, effective_s)
                if reason is None:
                    self.accepted += 1
                    self.last_command_s = effective_s
                    self.last_command = command.name
            if reason is not None:
                self._refuse(reason)

    def _refuse(self, reason: str) -> None:
        with self._lock:
            self.refused += 1
        log.warning("URScript refused: %s", reason)

    def _tick(self) -> None:
        with self._lock:
            self._ticks += 1
            self.arm.step(self.period_s, self._ticks * self.period_s)
            realtime = self._realtime_packet()
            state = self._robot_state() if self._ticks % self._secondary_every == 0 else None
            clients = list(self._clients.values())
        for client in clients:
            if client.kind == REALTIME:
                self._send(client, realtime)
                self.realtime_sent += 1
            elif state is not None:
                self._send(client, state)

    def _send(self, client: _Client, data: bytes) -> None:
        with self._lock:
            mute, latency = self._mute, self._latency_s
        if mute:
            return
        if latency > 0:
            self._outgoing.append((time.monotonic() + latency, client, data))
        else:
            self._write(client, data)

    def _flush_due(self, now: float) -> None:
        while self._outgoing and self._outgoing[0][0] <= now:
            _, client, data = self._outgoing.popleft()
            if client.sock.fileno() >= 0:
                self._write(client, data)

    def _flush_pending(self) -> None:
        for client in list(self._clients.values()):
            if client.outbox:
                self._write(client, b"")

    def _write(self, client: _Client, data: bytes) -> None:
        client.outbox += data
        try:
            sent = client.sock.send(client.outbox)
        except BlockingIOError:
            sent = 0
        except OSError:
            self._close(client, count=False)
            return
        del client.outbox[:sent]
        if len(client.outbox) > MAX_PENDING_OUT:
            log.warning("%s client %s too slow: dropped", client.kind, client.address)
            self._close(client, count=True)

    def _close(self, client: _Client, *, count: bool) -> None:
        fileno = client.sock.fileno()
        with self._lock:
            if self._clients.pop(fileno, None) is None:
                return
            if count:
                self.dropped_clients += 1
        with contextlib.suppress(KeyError, ValueError):
            self._selector.unregister(client.sock)
        client.sock.close()

    # ---- packets -------------------------------------------------------------------------------

    def _version_message(self) -> bytes:
        major, minor, bugfix = self.version
        return VersionMessage("URControl", major, minor, bugfix, 0, "ocu-sim").encode()

    def _realtime_packet(self) -> bytes:
        arm = self.arm
        time_s = self._ticks * self.period_s
        currents = vector6(
            [0.4 * a + 0.2 * math.tanh(10 * v) for a, v in zip(arm.qdd, arm.qd, strict=True)]
        )
        pose_target = tcp_pose(self.profile, arm.q)
        pose_actual = tcp_pose(self.profile, arm.q_actual)
        speed = vector6(
            [(t - a) / self.period_s for t, a in zip(pose_target[:3], pose_actual[:3], strict=True)]
            + [0.0, 0.0, 0.0]
        )
        values: dict[str, object] = {
            "time_s": time_s,
            "q_target": vector6(arm.q),
            "qd_target": vector6(arm.qd),
            "qdd_target": vector6(arm.qdd),
            "i_target": currents,
            "q_actual": vector6(arm.q_actual),
            "qd_actual": vector6(arm.qd_actual),
            "i_actual": currents,
            "i_control": currents,
            "tool_vector_actual": pose_actual,
            "tcp_speed_actual": speed,
            "tool_vector_target": pose_target,
            "tcp_speed_target": speed,
            "motor_temperatures": (35.0,) * JOINTS,
            "controller_timer_s": 0.0005,
            "robot_mode": float(RobotMode.RUNNING),
            "joint_modes": (253.0,) * JOINTS,
            "safety_mode": float(arm.safety_mode),
            "speed_scaling": 1.0,
            "v_main": 48.0,
            "v_robot": 48.0,
            "v_actual": (48.0,) * JOINTS,
        }
        if self.realtime_size >= 1060:
            values["program_state"] = 2.0 if arm.program_running else 1.0
        if self.realtime_size >= 1116:
            values["safety_status"] = float(arm.safety_mode)
        return realtime_state(self.realtime_size, **values).encode()

    def _robot_state(self) -> bytes:
        arm = self.arm
        major, minor = self.version[:2]
        if (major, minor) < (3, 2):
            limit, reserved = None, None
        elif (major, minor) < (3, 5):
            limit, reserved = 1.0, None
        else:
            limit, reserved = 1.0, 0
        mode = RobotModeData(
            timestamp_us=int(self._ticks * self.period_s * 1e6),
            emergency_stopped=arm.emergency_stopped,
            protective_stopped=arm.protective_stopped,
            program_running=arm.program_running,
            robot_mode=RobotMode.RUNNING,
            target_speed_fraction_limit=limit,
            reserved=reserved,
        )
        joints = JointData(
            tuple(
                JointState(
                    q_actual=arm.q_actual[i],
                    q_target=arm.q[i],
                    qd_actual=arm.qd_actual[i],
                    voltage=48.0,
                    motor_temperature=35.0,
                )
                for i in range(JOINTS)
            )
        )
        board = MasterboardData(safety_mode=arm.safety_mode)
        return RobotState((mode, joints, board)).encode()


# ---- command line ----------------------------------------------------------------------------


def _version(text: str) -> tuple[int, int, int]:
    try:
        parts = tuple(int(p) for p in text.split("."))
    except ValueError:
        parts = ()
    if len(parts) != 3:
        raise argparse.ArgumentTypeError(f"{text!r} is not MAJOR.MINOR.BUGFIX")
    try:
        realtime_size(parts[:2])
    except UrProtocolError as err:
        raise argparse.ArgumentTypeError(str(err)) from err
    return (parts[0], parts[1], parts[2])


def build_parser() -> argparse.ArgumentParser:
    """The UR simulator's command line."""
    parser = argparse.ArgumentParser(
        prog="ocu-sim --profile UR_PROFILE",
        description="A Universal Robots controller simulator: ports 30001-30003 over TCP. "
        "SIGUSR1 drops every connection and refuses new ones, SIGUSR2 accepts again.",
    )
    parser.add_argument(
        "--profile",
        default="ur5e",
        help=f"a shipped UR profile ({', '.join(shipped_ur_profiles())}) or a TOML file",
    )
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument(
        "--port-base",
        type=int,
        default=30000,
        help="the ports are BASE+1 (primary), +2 (secondary), +3 (realtime); 0: any free",
    )
    parser.add_argument(
        "--controller-version", type=_version, default=None, help="e.g. 3.2.0 or 5.10.0"
    )
    parser.add_argument("--latency-ms", type=float, default=0.0, help="one-way delay, each way")
    parser.add_argument(
        "--exit-with-parent",
        action="store_true",
        help="stop when standard input (a pipe from the parent) closes",
    )
    parser.add_argument("--log-level", default="INFO")
    return parser


def is_ur_profile(argv: Sequence[str]) -> bool:
    """Whether a command line's --profile names a shipped UR profile (ocu-sim dispatches)."""
    names = shipped_ur_profiles()
    for index, arg in enumerate(argv):
        if arg == "--profile" and index + 1 < len(argv):
            return argv[index + 1] in names
        if arg.startswith("--profile="):
            return arg.split("=", 1)[1] in names
    return False


def main(argv: Sequence[str] | None = None) -> int:
    """Run the UR simulator until SIGINT or SIGTERM."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        profile = load_ur_profile(args.profile)
    except ProfileError as err:
        parser.error(str(err))
    logging.basicConfig(
        level=args.log_level, format="%(asctime)s %(levelname)s %(name)s: %(message)s"
    )
    base = args.port_base
    ports = (0, 0, 0) if base == 0 else (base + 1, base + 2, base + 3)
    simulator = UrSimulator(
        profile,
        host=args.host,
        ports=ports,
        controller_version=args.controller_version,
        latency_ms=args.latency_ms,
    )
    stop = threading.Event()

    def on_signal(signum: int, _frame: FrameType | None) -> None:
        if signum == signal.SIGUSR1:
            simulator.cut()
        elif signum == signal.SIGUSR2:
            simulator.restore()
        else:
            stop.set()

    for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGUSR1, signal.SIGUSR2):
        signal.signal(signum, on_signal)
    if args.exit_with_parent:

        def wait_for_parent() -> None:
            while sys.stdin.buffer.read(4096):
                pass
            stop.set()

        threading.Thread(target=wait_for_parent, name="ur-sim-stdin", daemon=True).start()
    simulator.start()
    ports_text = " ".join(f"{kind}={port}" for kind, port in simulator.ports.items())
    print(f"ocu-sim ur listening on {args.host} {ports_text}", flush=True)
    stop.wait()
    simulator.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
