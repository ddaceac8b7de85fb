"""An xArm 1S simulator on a pseudo-terminal: the board's protocol and six simulated servos.

`XarmSimulator(profile).start()` opens a pseudo-terminal and returns the path of its serial
end (/dev/pts/N), which any serial client opens as it would /dev/ttyUSB0
(`ocu-sim --profile xarm1s` prints it). The board (docs/xarm.md): CMD_SERVO_MOVE moves the
named servos, CMD_MULT_SERVO_POS_READ and CMD_GET_BATTERY_VOLTAGE are answered; other frames
are counted and ignored, garbage is skipped by the frame reader and counted.

A servo (`Servo`): "go to P within T" moves its setpoint linearly from where the setpoint is
to P over T (at most at the servo's top speed; the board's own interpolation is not
documented: assumed), and the shaft follows the setpoint through seed 003's identified
second-order model, x'' = ωn² (r - x) - 2 ξ ωn x', integrated in 1 ms steps. So a stream of
short moves that stops leaves the setpoint at the last move's target: the servos stop by
their own nature.

The board's servo bus is shared: each servo read takes `SERVO_READ_S` and each servo written
`SERVO_WRITE_S`, one after another; frames that arrive meanwhile wait their turn (assumed
figures: docs/xarm.md). Faults like the other simulators': `latency_ms` delays every frame
each way, `garbage_rate` puts random bytes before a reply with that probability,
`noise_units` adds Gaussian noise to the positions read, `mute` answers nothing (moves are
still obeyed).

A hidden mounting truth to calibrate against (`ocu calibrate`, docs/calibration.md "An xArm
1S"): `mounting` gives a servo the offset (units) at which its joint is truly at 0 rad and
whether its horn is mounted reversed; `absent` servos are not on the bus (never answer). The
arm starts in its true zero pose; `true_angles_rad` is the ground truth the profile's angles
are checked against.
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import heapq
import logging
import math
import os
import random
import select
import signal
import sys
import threading
import time
import tty
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass
from types import FrameType

from ocu.profile.keys import ProfileError
from ocu.profile.xarm import (
    CENTRE_UNITS,
    XarmProfile,
    is_xarm_file,
    load_xarm_profile,
    shipped_xarm_profiles,
)
from ocu.protocol.xarm import (
    Cmd,
    Direction,
    Frame,
    FrameReader,
    ServoMove,
    XarmProtocolError,
    battery_reply,
    decode_position_request,
    decode_servo_move,
    positions_reply,
)

log = logging.getLogger("ocu.sim.xarm")

#: The servo model's integration step.
STEP_S = 0.001
#: The board's servo bus: one servo read, one servo written (assumed: an LX servo's read
#: takes a request and a reply of about ten bytes each at 115200 baud, and its reply delay).
SERVO_READ_S = 0.002
SERVO_WRITE_S = 0.001
#: The loop wakes at least this often (to write replies that came due).
MAX_WAIT_S = 0.005
DEFAULT_BATTERY_MV = 7400
#: Moves remembered for `moves_since`.
MOVE_LOG = 4096
#: How often `main` looks at the signals its handlers noted.
SIGNAL_POLL_S = 0.1


class Servo:
    """One servo: a setpoint moving linearly over each move's time, the shaft following it."""

    def __init__(
        self,
        position: float,
        *,
        damping_ratio: float,
        natural_frequency_rad_s: float,
        max_speed_units_s: float,
        now: float,
    ) -> None:
        self.zeta = damping_ratio
        self.omega = natural_frequency_rad_s
        self.max_speed_units_s = max_speed_units_s
        self.position = float(position)
        self.velocity = 0.0
        self._from = float(position)
        self._to = float(position)
        self._start = now
        self._duration = 0.0
        self._time = now

    def setpoint(self, now: float) -> float:
        """Where the servo is told to be at `now`."""
        if self._duration <= 0.0 or now >= self._start + self._duration:
            return self._to
        fraction = max(0.0, (now - self._start) / self._duration)
        return self._from + (self._to - self._from) * fraction

    @property
    def target(self) -> float:
        """The last move's target."""
        return self._to

    @property
    def move_ends_at(self) -> float:
        """When the setpoint reaches the last move's target."""
        return self._start + self._duration

    def move(self, target: float, duration_s: float, now: float) -> None:
        """Go to `target` within `duration_s` from `now` (no faster than the top speed)."""
        self.advance(now)
        start = self.setpoint(now)
        self._from, self._to, self._start = start, float(target), now
        self._duration = max(duration_s, abs(target - start) / self.max_speed_units_s)

    def advance(self, now: float) -> None:
        """Integrate the shaft up to `now`."""
        omega2 = self.omega * self.omega
        damping = 2.0 * self.zeta * self.omega
        while self._time + STEP_S <= now:
            self._time += STEP_S
            reference = self.setpoint(self._time)
            acceleration = omega2 * (reference - self.position) - damping * self.velocity
            self.velocity += acceleration * STEP_S  # semi-implicit Euler: stable at 1 ms
            self.position += self.velocity * STEP_S


@dataclass(frozen=True)
class Mounting:
    """How a servo truly sits in the arm: the joint is at 0 rad at 500 + `offset_units`, and
    a rising position turns it the negative way when `reversed`."""

    offset_units: int = 0
    reversed: bool = False

    def angle_rad(self, position: float, units_per_rad: float) -> float:
        """The joint's true angle at this servo position."""
        sign = -1.0 if self.reversed else 1.0
        return sign * (position - CENTRE_UNITS - self.offset_units) / units_per_rad


def parse_mounting(text: str) -> tuple[int, Mounting]:
    """`SERVO:OFFSET[:reversed]` (ocu-sim --mount) as (servo, Mounting); ValueError if bad."""
    parts = text.split(":")
    if len(parts) not in (2, 3) or (len(parts) == 3 and parts[2] != "reversed"):
        raise ValueError(f"bad mounting {text!r}: use SERVO:OFFSET[:reversed], e.g. 4:-40:reversed")
    try:
        servo, offset = int(parts[0]), int(parts[1])
    except ValueError as err:
        raise ValueError(f"bad mounting {text!r}: SERVO and OFFSET are integers") from err
    return servo, Mounting(offset, len(parts) == 3)


@dataclass(frozen=True)
class XarmSnapshot:
    """The simulated arm at one time (servo id -> value, in servo units)."""

    time: float
    positions: Mapping[int, float]
    velocities: Mapping[int, float]
    setpoints: Mapping[int, float]
    targets: Mapping[int, float]
    moves: int
    position_reads: int
    battery_reads: int
    bad_frames: int
    ignored_frames: int
    last_move: ServoMove | None
    last_move_at: float | None


class XarmBoard:
    """The board's protocol and servos, driven by a clock; no I/O (the simulator does it)."""

    def __init__(
        self,
        profile: XarmProfile,
        *,
        clock: Callable[[], float] = time.monotonic,
        latency_ms: float = 0.0,
        garbage_rate: float = 0.0,
        noise_units: float = 0.0,
        battery_mv: int = DEFAULT_BATTERY_MV,
        initial: Mapping[int, float] | None = None,
        seed: int | None = None,
        mounting: Mapping[int, Mounting] | None = None,
        absent: Collection[int] = (),
    ) -> None:
        self.profile = profile
        self.clock = clock
        self.mounting = {joint.servo: Mounting() for joint in profile.joints} | dict(mounting or {})
        self.absent = frozenset(absent)
        self.latency_s = latency_ms / 1000.0
        self.garbage_rate = garbage_rate
        self.noise_units = noise_units
        self.battery_mv = battery_mv
        self.mute = False
        self._random = random.Random(seed)
        self._lock = threading.Lock()
        now = clock()
        max_speed = profile.servo.max_speed_rad_s * profile.units_per_rad
        self.servos: dict[int, Servo] = {
            joint.servo: Servo(
                (initial or {}).get(
                    joint.servo, CENTRE_UNITS + self.mounting[joint.servo].offset_units
                ),
                damping_ratio=profile.servo.damping_ratio,
                natural_frequency_rad_s=profile.servo.natural_frequency_rad_s,
                max_speed_units_s=max_speed,
                now=now,
            )
            for joint in profile.joints
        }
        self._reader = FrameReader(Direction.TO_BOARD)
        self._inbox: list[tuple[float, int, Frame]] = []  # (due, order, frame)
        self._outbox: collections.deque[tuple[float, bytes]] = collections.deque()
        self._order = 0
        self._bus_free_at = now
        self._moves: collections.deque[tuple[float, ServoMove]] = collections.deque(maxlen=MOVE_LOG)
        self._counts = collections.Counter[str]()

    # ---- bytes in and out -------------------------------------------------------------------

    def receive(self, data: bytes) -> None:
        """Bytes from the serial line: frames are queued to run after the latency."""
        now = self.clock()
        with self._lock:
            for frame in self._reader.feed(data):
                self._order += 1
                heapq.heappush(self._inbox, (now + self.latency_s, self._order, frame))

    def run_due(self) -> None:
        """Run the frames whose time has come (in order, each after the bus is free)."""
        now = self.clock()
        with self._lock:
            while self._inbox and self._inbox[0][0] <= now:
                due, _, frame = heapq.heappop(self._inbox)
                start = max(due, self._bus_free_at)
                self._run(frame, start)

    def take_output(self) -> bytes:
        """The reply bytes due now (nothing while muted: they are dropped)."""
        now = self.clock()
        out = bytearray()
        with self._lock:
            while self._outbox and self._outbox[0][0] <= now:
                out += self._outbox.popleft()[1]
        return b"" if self.mute else bytes(out)

    def next_due(self) -> float | None:
        """When the next queued frame or reply comes due (None: nothing queued)."""
        with self._lock:
            times = [self._inbox[0][0]] if self._inbox else []
            if self._outbox:
                times.append(self._outbox[0][0])
        return min(times) if times else None

    # ---- the commands -----------------------------------------------------------------------

    def _run(self, frame: Frame, start: float) -> None:
        try:
            if frame.command == Cmd.SERVO_MOVE:
                move = decode_servo_move(frame.parameters)
                for servo_id, position in move.positions:
                    servo = self.servos.get(servo_id)
                    if servo is not None and servo_id not in self.absent:
                        servo.move(position, move.duration_ms / 1000.0, start)
                self._bus_free_at = start + SERVO_WRITE_S * len(move.positions)
                self._moves.append((start, move))
                self._counts["moves"] += 1
            elif frame.command == Cmd.MULT_SERVO_POS_READ:
                wanted = decode_position_request(frame.parameters)
                done = start + SERVO_READ_S * len(wanted)
                self._bus_free_at = done
                readings = {}
                for servo_id in wanted:
                    servo = self.servos.get(servo_id)
                    if servo is None or servo_id in self.absent:
                        continue  # no reply from a servo not on the bus
                    servo.advance(done)
                    noise = self._random.gauss(0.0, self.noise_units) if self.noise_units else 0.0
                    readings[servo_id] = round(servo.position + noise)
                self._reply(positions_reply(readings), done)
                self._counts["position_reads"] += 1
            elif frame.command == Cmd.GET_BATTERY_VOLTAGE:
                self._reply(battery_reply(self.battery_mv), start)
                self._counts["battery_reads"] += 1
            else:
                self._counts["ignored"] += 1
        except XarmProtocolError as err:
            self._counts["ignored"] += 1
            log.info("frame ignored: %s", err)

    def _reply(self, data: bytes, ready: float) -> None:
        if self.garbage_rate and self._random.random() < self.garbage_rate:
            data = self._random.randbytes(self._random.randint(1, 8)) + data
        self._outbox.append((ready + self.latency_s, data))

    # ---- what it did ------------------------------------------------------------------------

    def snapshot(self) -> XarmSnapshot:
        """The servos now and the counters."""
        now = self.clock()
        with self._lock:
            for servo in self.servos.values():
                servo.advance(now)
            last = self._moves[-1] if self._moves else None
            return XarmSnapshot(
                time=now,
                positions={k: s.position for k, s in self.servos.items()},
                velocities={k: s.velocity for k, s in self.servos.items()},
                setpoints={k: s.setpoint(now) for k, s in self.servos.items()},
                targets={k: s.target for k, s in self.servos.items()},
                moves=self._counts["moves"],
                position_reads=self._counts["position_reads"],
                battery_reads=self._counts["battery_reads"],
                bad_frames=self._reader.bad_frames,
                ignored_frames=self._counts["ignored"],
                last_move=last[1] if last else None,
                last_move_at=last[0] if last else None,
            )

    def true_angles_rad(self) -> dict[int, float]:
        """Ground truth: each servo's joint angle now by its mounting (rad)."""
        snapshot = self.snapshot()
        return {
            servo: self.mounting[servo].angle_rad(position, self.profile.units_per_rad)
            for servo, position in snapshot.positions.items()
        }

    def moves_since(self, since: float) -> list[tuple[float, ServoMove]]:
        """The moves run at or after `since` (time, move), oldest first."""
        with self._lock:
            return [(t, move) for t, move in self._moves if t >= since]


class XarmSimulator:
    """The board on a pseudo-terminal, in its own thread ("ocu-xarm-sim")."""

    def __init__(
        self,
        profile: XarmProfile,
        *,
        latency_ms: float = 0.0,
        garbage_rate: float = 0.0,
        noise_units: float = 0.0,
        battery_mv: int = DEFAULT_BATTERY_MV,
        initial: Mapping[int, float] | None = None,
        seed: int | None = None,
        mounting: Mapping[int, Mounting] | None = None,
        absent: Collection[int] = (),
    ) -> None:
        self.board = XarmBoard(
            profile,
            latency_ms=latency_ms,
            garbage_rate=garbage_rate,
            noise_units=noise_units,
            battery_mv=battery_mv,
            initial=initial,
            seed=seed,
            mounting=mounting,
            absent=absent,
        )
        self.profile = profile
        self.path = ""
        self.dropped_bytes = 0
        self._master = -1
        self._slave = -1
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> str:
        """Open the pseudo-terminal and serve it; the path of its serial end."""
        if self._thread is not None:
            return self.path
        self._master, self._slave = os.openpty()
        # Raw: the line discipline must pass every byte as it is (no echo, no CR/LF mapping).
        tty.setraw(self._slave)
        # The simulator keeps the serial end open too, so that a client closing it and
        # opening it again does not hang up the board's end.
        os.set_blocking(self._master, False)
        self.path = os.ttyname(self._slave)
        self._thread = threading.Thread(target=self._run, name="ocu-xarm-sim", daemon=True)
        self._thread.start()
        log.info("xArm simulator on %s", self.path)
        return self.path

    def snapshot(self) -> XarmSnapshot:
        """The servos now and the counters."""
        return self.board.snapshot()

    def set_mute(self, mute: bool) -> None:
        """Answer nothing (True) or answer again (False)."""
        self.board.mute = mute

    def _run(self) -> None:
        while not self._stop.is_set():
            now = self.board.clock()
            due = self.board.next_due()
            timeout = MAX_WAIT_S if due is None else min(MAX_WAIT_S, max(0.0, due - now))
            try:
                readable, _, _ = select.select([self._master], [], [], timeout)
            except (OSError, ValueError):
                break
            if readable:
                try:
                    data = os.read(self._master, 4096)
                except BlockingIOError:
                    data = b""
                except OSError:  # EIO: no client has the serial end open just now
                    data = b""
                if data:
                    self.board.receive(data)
            self.board.run_due()
            out = self.board.take_output()
            if out:
                self._write(out)

    def _write(self, data: bytes) -> None:
        try:
            written = os.write(self._master, data)
        except BlockingIOError:
            written = 0
        except OSError:
            written = 0
        # Nobody reading: the terminal's buffer is full, and what does not fit is lost.
        self.dropped_bytes += len(data) - written

    def stop(self) -> None:
        """Stop serving and close the pseudo-terminal; idempotent."""
        self._stop.set()
        thread, self._thread = self._thread, None
        if thread is not None:
            thread.join(2.0)
        for fd in (self._master, self._slave):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._master = self._slave = -1


def step_response(
    profile: XarmProfile, *, step_units: float = 100.0, duration_s: float = 6.0
) -> list[tuple[float, float]]:
    """A servo's simulated response to a step of its setpoint (time from the step, units).

    The setpoint moves at the servo's top speed (a move of duration 0), as a real servo's
    does; sampled every 10 ms.
    """
    servo = Servo(
        0.0,
        damping_ratio=profile.servo.damping_ratio,
        natural_frequency_rad_s=profile.servo.natural_frequency_rad_s,
        max_speed_units_s=profile.servo.max_speed_rad_s * profile.units_per_rad,
        now=0.0,
    )
    servo.move(step_units, 0.0, 0.0)
    samples = []
    for index in range(round(duration_s / 0.01) + 1):
        now = index * 0.01
        servo.advance(now + 1e-9)
        samples.append((now, servo.position))
    return samples


def step_figures(samples: Sequence[tuple[float, float]], final: float) -> tuple[float, float]:
    """Overshoot (% of the step) and settling time (s, within 2 % of it for good)."""
    peak = max(value for _, value in samples)
    overshoot = 100.0 * (peak - final) / final
    settled = 0.0
    for when, value in samples:
        if abs(value - final) > 0.02 * abs(final):
            settled = when
    return overshoot, settled


def phase_margin_deg(profile: XarmProfile, delay_s: float = 0.0) -> float:
    """The phase margin of the servo model taken as an open loop (seed 003 §4.1 does so),
    with a pure delay: where |G(jω)| = 1, 180° plus G's phase minus ωτ."""
    zeta = profile.servo.damping_ratio
    omega_n = profile.servo.natural_frequency_rad_s
    # |G(jω)| = 1  <=>  ω⁴ + (4ζ² - 2) ωn² ω² = 0: ω² = (2 - 4ζ²) ωn².
    squared = (2.0 - 4.0 * zeta * zeta) * omega_n * omega_n
    if squared <= 0.0:
        return math.inf  # |G| never reaches 1 again: no crossover
    omega = math.sqrt(squared)
    phase = -math.atan2(2.0 * zeta * omega_n * omega, omega_n * omega_n - squared)
    return math.degrees(math.pi + phase - omega * delay_s)


def is_xarm_profile(argv: Sequence[str]) -> bool:
    """Whether a command line's --profile names an xArm profile, shipped or a file in the
    xArm format (ocu-sim dispatches)."""
    for index, arg in enumerate(argv):
        if arg == "--profile" and index + 1 < len(argv):
            return _is_xarm(argv[index + 1])
        if arg.startswith("--profile="):
            return _is_xarm(arg.split("=", 1)[1])
    return False


def _is_xarm(name: str) -> bool:
    return name in shipped_xarm_profiles() or is_xarm_file(name)


def build_parser() -> argparse.ArgumentParser:
    """ocu-sim's options for an xArm."""
    parser = argparse.ArgumentParser(
        prog="ocu-sim", description="Simulate an xArm 1S's board on a pseudo-terminal."
    )
    parser.add_argument("--profile", default="xarm1s", help="xArm profile name or TOML file")
    parser.add_argument("--latency-ms", type=float, default=0.0, help="delay each way (ms)")
    parser.add_argument(
        "--garbage", type=float, default=0.0, metavar="P", help="garbage before a reply: P 0-1"
    )
    parser.add_argument(
        "--noise", type=float, default=0.0, metavar="UNITS", help="position noise (σ, units)"
    )
    parser.add_argument("--battery-mv", type=int, default=DEFAULT_BATTERY_MV)
    parser.add_argument(
        "--mount",
        action="append",
        default=[],
        metavar="SERVO:OFFSET[:reversed]",
        help="a hidden mounting truth: the servo's joint is at 0 rad at 500 + OFFSET (the arm "
        "starts there), reversed if said (repeatable)",
    )
    parser.add_argument(
        "--absent",
        action="append",
        type=int,
        default=[],
        metavar="SERVO",
        help="a servo not on the bus: it never answers (repeatable)",
    )
    parser.add_argument(
        "--exit-with-parent", action="store_true", help="stop when standard input ends"
    )
    parser.add_argument(
        "--log-level", default="WARNING", choices=("DEBUG", "INFO", "WARNING", "ERROR")
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the xArm simulator until SIGINT or SIGTERM (SIGUSR1 mutes it, SIGUSR2 unmutes)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        profile = load_xarm_profile(args.profile)
    except ProfileError as err:
        parser.error(str(err))
    if not 0.0 <= args.garbage <= 1.0 or args.latency_ms < 0 or args.noise < 0:
        parser.error("--garbage must be 0-1; --latency-ms and --noise must be >= 0")
    try:
        mounting = dict(parse_mounting(text) for text in args.mount)
    except ValueError as err:
        parser.error(str(err))
    servos = {joint.servo for joint in profile.joints}
    unknown = sorted((mounting.keys() | set(args.absent)) - servos)
    if unknown:
        parser.error(f"--mount/--absent: no servo {unknown} in the profile ({sorted(servos)})")
    logging.basicConfig(
        level=args.log_level, format="%(asctime)s %(levelname)s %(name)s: %(message)s"
    )
    simulator = XarmSimulator(
        profile,
        latency_ms=args.latency_ms,
        garbage_rate=args.garbage,
        noise_units=args.noise,
        battery_mv=args.battery_mv,
        mounting=mounting,
        absent=args.absent,
    )
    stop = threading.Event()

    def on_signal(signum: int, _frame: FrameType | None) -> None:
        if signum == signal.SIGUSR1:
            simulator.set_mute(True)
        elif signum == signal.SIGUSR2:
            simulator.set_mute(False)
        else:
            stop.set()

    for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGUSR1, signal.SIGUSR2):
        signal.signal(signum, on_signal)
    if args.exit_with_parent:

        def wait_for_parent() -> None:
            while sys.stdin.buffer.read(4096):
                pass
            stop.set()

        threading.Thread(target=wait_for_parent, name="xarm-sim-stdin", daemon=True).start()
    path = simulator.start()
    print(f"ocu-sim {profile.name} on {path}", flush=True)
    # Woken now and then: a signal the kernel hands to another thread (the simulator's, the
    # stdin reader's) runs its Python handler only when the main thread next runs.
    while not stop.wait(SIGNAL_POLL_S):
        pass
    simulator.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
