"""`ocu probe` and `ocu calibrate` on the command line (docs/calibration.md).

Exit status: 0 when everything matched (probe) or was measured (calibrate), 1 when something
contradicts the profile, was not found, or the calibration was stopped; 2 for bad arguments,
a bad profile or a bad answers file.

`ocu calibrate` moves the robot. With `--yes` (or `--on-stand`) it assumes a robot on a
stand and needs no deadman; otherwise the operator holds Enter on the terminal while the
robot may move (the terminal's key repeat keeps the deadman held; letting go stops it at
once). Ctrl-C or SIGTERM stop the robot at any time; zeros are the last thing sent.
"""

from __future__ import annotations

import argparse
import logging
import math
import queue
import signal
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import TextIO

from ocu.calibrate.guard import CalibrationAbortedError, Deadman, OnStand, StopSignal
from ocu.calibrate.operator import (
    AnswersError,
    AnswersOperator,
    AutoOperator,
    Operator,
    TerminalOperator,
)
from ocu.calibrate.probe import DEFAULT_LISTEN_S, run_probe
from ocu.calibrate.raw import raw_profile
from ocu.calibrate.session import CalibrationConfig, Calibrator
from ocu.calibrate.writer import write_calibrated_profile
from ocu.calibrate.xarm_cli import calibrate_xarm, is_xarm_profile_arg
from ocu.link.base import LinkError
from ocu.link.live import UdpLink
from ocu.profile import ProfileError, default_profile_path, load_profile_data, parse_profile

log = logging.getLogger("ocu.calibrate")

# Enter held down repeats about 25-30 times a second after a first delay of up to 0.66 s
# (X11's default): the deadman counts as held this long after the last line.
TERMINAL_HOLD_S = 0.7
# How often a question waiting for its answer looks at the stop signal.
ANSWER_POLL_S = 0.05


def _address(text: str, default_port: int) -> tuple[str, int]:
    host, sep, port_text = text.rpartition(":")
    if not sep:
        return text, default_port
    if not port_text.isdigit() or not 1 <= int(port_text) <= 65535 or not host:
        raise argparse.ArgumentTypeError(f"bad address {text!r}: use HOST[:PORT]")
    return host, int(port_text)


def _common(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--robot", required=True, metavar="HOST[:PORT]", help="the robot (port: the profile's)"
    )
    parser.add_argument("--profile", metavar="FILE", help="robot profile (default: the Engineer)")
    parser.add_argument("--log-level", default="WARNING")


def probe_parser() -> argparse.ArgumentParser:
    """Options of `ocu probe`."""
    parser = argparse.ArgumentParser(
        prog="ocu probe",
        description="Listen to a robot and report, in plain sentences, what arrives and where "
        "it contradicts the profile. Sends only remote-control packets with every axis zero. "
        "Exit status 0 when everything matches the profile, 1 otherwise.",
    )
    _common(parser)
    parser.add_argument(
        "--seconds", type=float, default=DEFAULT_LISTEN_S, help="how long to listen (%(default)s)"
    )
    return parser


def probe_main(argv: Sequence[str]) -> int:
    """`ocu probe`."""
    parser = probe_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=args.log_level.upper(), format="%(asctime)s %(name)s %(message)s")
    if not (math.isfinite(args.seconds) and args.seconds > 0):
        parser.error("--seconds must be > 0")
    try:
        profile = parse_profile(load_profile_data(args.profile), _source(args.profile))
        address = _address(args.robot, profile.link.port)
        link = UdpLink(profile, address, extension=False, gui_alive_timeout_s=None)
    except ProfileError as err:
        print(f"ocu probe: error: {err}", file=sys.stderr)
        return 2
    except (argparse.ArgumentTypeError, LinkError) as err:
        parser.error(str(err))
    stop = StopSignal()
    with _stop_on_signals(stop):
        report = run_probe(link, profile, listen_s=args.seconds, stop=stop)
    print(report.text(), flush=True)
    return 0 if report.ok else 1


def calibrate_parser() -> argparse.ArgumentParser:
    """Options of `ocu calibrate`."""
    parser = argparse.ArgumentParser(
        prog="ocu calibrate",
        description="Find the robot's axis map, directions, joint scales, ticks per radian and "
        "zero offsets (and, guided, limits and drive constants) by moving it a little, and "
        "write a profile that says how each key was measured. Ctrl-C stops the robot.",
    )
    _common(parser)
    parser.add_argument("--out", required=True, type=Path, metavar="PROFILE.toml")
    parser.add_argument(
        "--yes",
        action="store_true",
        help="the automatic steps only, no questions, no deadman: a robot on a stand "
        "(the device ID -> joint map of the profile is kept)",
    )
    parser.add_argument(
        "--answers",
        type=Path,
        metavar="FILE",
        help="the guided mode with its answers from a TOML file (docs/calibration.md)",
    )
    parser.add_argument(
        "--on-stand",
        action="store_true",
        help="no deadman in the guided mode: the robot is on a stand (implied by --yes)",
    )
    parser.add_argument(
        "--telemetry-hz",
        type=float,
        default=None,
        help="telemetry rate to expect before measuring it (default: the profile's)",
    )
    return parser


def calibrate_main(
    argv: Sequence[str], stdin: TextIO | None = None, stdout: TextIO | None = None
) -> int:
    """`ocu calibrate`.

    Ctrl-C and SIGTERM set the stop signal from the first line to the last (never a
    KeyboardInterrupt): before the calibration nothing moves and nothing is written; during it
    the robot stops; after it the file is not written, and a stop that comes while it is being
    written lets the write finish (atomic, milliseconds): the file is complete or absent.
    """
    stop = StopSignal()
    with _stop_on_signals(stop):
        return _calibrate(argv, stdin, stdout, stop)


def _calibrate(
    argv: Sequence[str], stdin: TextIO | None, stdout: TextIO | None, stop: StopSignal
) -> int:
    parser = calibrate_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=args.log_level.upper(), format="%(asctime)s %(name)s %(message)s")
    out = stdout or sys.stdout
    if is_xarm_profile_arg(args.profile):
        return calibrate_xarm(parser, args, stdin, out, stop)
    if args.yes and args.answers:
        parser.error("--yes asks nothing: --answers does not apply")
    if args.telemetry_hz is not None and not (
        math.isfinite(args.telemetry_hz) and args.telemetry_hz > 0
    ):
        parser.error("--telemetry-hz must be > 0")
    try:
        base = load_profile_data(args.profile)
        profile = parse_profile(base, _source(args.profile))
        if args.telemetry_hz is not None:
            # Only what the calibration expects at first (its waits); the profile written
            # keeps the base's rate.
            profile = replace(
                profile, link=replace(profile.link, telemetry_rate_hz=args.telemetry_hz)
            )
        operator: Operator = (
            AutoOperator(lambda text: print(text, file=out, flush=True))
            if args.yes
            else AnswersOperator.from_file(args.answers, lambda t: print(t, file=out, flush=True))
            if args.answers
            else TerminalOperator(stdin, out)
        )
        address = _address(args.robot, profile.link.port)
        link = UdpLink(raw_profile(profile), address, extension=False)
    except (ProfileError, AnswersError) as err:
        print(f"ocu calibrate: error: {err}", file=sys.stderr)
        return 2
    except (argparse.ArgumentTypeError, LinkError) as err:
        parser.error(str(err))
    if not args.out.parent.is_dir():
        parser.error(f"--out: no directory {args.out.parent}")
    if stop.stopped:  # before anything moved
        link.shutdown()
        print(f"stopped: {stop.reason}; nothing written", file=out, flush=True)
        return 1
    deadman: Deadman = OnStand()
    held_enter = not (args.yes or args.on_stand)
    if held_enter or isinstance(operator, TerminalOperator):
        # One reader of the terminal: the held Enter key, and answers that a stop interrupts
        # (a question waiting on a bare readline would outlast Ctrl-C).
        terminal = TerminalDeadman(stdin or sys.stdin, stop)
        if isinstance(operator, TerminalOperator):
            operator = HeldEnterOperator(operator, terminal)
        if held_enter:
            deadman = terminal
    if held_enter:
        print(
            "Hold Enter while the robot may move; let go to stop it. Ctrl-C stops everything.",
            file=out,
            flush=True,
        )
    config = CalibrationConfig()
    calibrator = Calibrator(link, profile, operator, deadman=deadman, stop=stop, config=config)
    try:
        result = calibrator.run()
    finally:
        link.shutdown()  # zeros last
    for finding in result.findings:
        print(f"{finding.level}: {finding.text}", file=out)
    excursion = max(result.excursion_deg.values(), default=0.0)
    print(
        f"calibration took {result.duration_s:.1f} s; largest joint excursion "
        f"{excursion:.1f}° (as reckoned from the readings)",
        file=out,
    )
    if result.aborted is not None or stop.stopped:
        print(f"stopped: {result.aborted or stop.reason}; nothing written", file=out, flush=True)
        return 1
    try:
        write_calibrated_profile(
            args.out,
            base,
            result,
            robot=f"{address[0]}:{address[1]}",
            base_name=_source(args.profile),
        )
    except (ProfileError, OSError) as err:
        print(f"ocu calibrate: cannot write {args.out}: {err}", file=sys.stderr)
        return 1
    print(
        f"wrote {args.out}: {len(result.measured)} key(s) measured; use it with "
        f"`ocu --profile {args.out}`",
        file=out,
        flush=True,
    )
    if stop.stopped:
        print(f"stopped: {stop.reason} while writing; the file is complete", file=out, flush=True)
        return 1
    return 0 if result.complete else 1


def _source(path: str | None) -> str:
    return str(path) if path is not None else str(default_profile_path())


class _stop_on_signals:  # noqa: N801 - used as a context manager, named like one
    """SIGINT and SIGTERM stop the robot (the calibrator notices within one control step)."""

    def __init__(self, stop: StopSignal) -> None:
        self.stop = stop
        self._previous: dict[int, object] = {}

    def __enter__(self) -> None:
        if threading.current_thread() is not threading.main_thread():
            return
        for sig in (signal.SIGINT, signal.SIGTERM):
            self._previous[sig] = signal.signal(
                sig, lambda signum, _frame: self.stop.stop(signal.Signals(signum).name)
            )

    def __exit__(self, *exc: object) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)  # type: ignore[arg-type]


class TerminalDeadman:
    """The deadman on a terminal: held while Enter is held (its key repeat keeps coming).

    One thread reads standard input line by line: empty lines while a motion runs are the
    held Enter key; other lines are answers for the operator's questions.
    """

    def __init__(self, stdin: TextIO, stop: StopSignal) -> None:
        self._stdin = stdin
        self._stop = stop
        self._lock = threading.Lock()
        self._last_line_at = -math.inf
        self.answers: queue.Queue[str | None] = queue.Queue()
        self._thread = threading.Thread(target=self._read, name="ocu-terminal", daemon=True)
        self._thread.start()

    def _read(self) -> None:
        for line in self._stdin:
            with self._lock:
                self._last_line_at = time.monotonic()
            self.answers.put(line.rstrip("\n"))
        self.answers.put(None)

    def held(self) -> bool:
        """Whether a line came within the hold window."""
        with self._lock:
            return time.monotonic() - self._last_line_at < TERMINAL_HOLD_S

    def next_answer(self) -> str | None:
        """The next line typed (None at the end of input); CalibrationAbortedError on a stop."""
        while True:
            try:
                return self.answers.get(timeout=ANSWER_POLL_S)
            except queue.Empty:
                if self._stop.stopped:
                    raise CalibrationAbortedError(self._stop.reason) from None

    def released(self) -> None:
        """Wait until Enter is let go, then forget the repeats it left."""
        while self.held() and not self._stop.stopped:
            self._stop.wait(0.05)
        while not self.answers.empty():
            self.answers.get_nowait()


class HeldEnterOperator(TerminalOperator):
    """A terminal operator whose answers come through the deadman's reader."""

    def __init__(self, inner: TerminalOperator, deadman: TerminalDeadman) -> None:
        super().__init__(inner._in, inner._stdout)
        self._deadman = deadman

    def _ask(self, question: str) -> str:
        self._deadman.released()
        self._stdout.write(f"{question} ")
        self._stdout.flush()
        answer = self._deadman.next_answer()
        if answer is None:
            raise EOFError("no more answers on standard input")
        return answer.strip()
