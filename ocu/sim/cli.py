"""Command line of the simulator: `ocu-sim` and `python -m ocu.sim`.

Signals: SIGUSR1 cuts the link, SIGUSR2 restores it, SIGINT and SIGTERM stop cleanly (exit 0).
With --exit-with-parent, the end of standard input stops it the same way (see launcher.py).
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import signal
import sys
import threading
from collections.abc import Sequence

from ocu.nav.world import DEFAULT_WORLD, WorldError, load_world
from ocu.net.transport import TransportError
from ocu.profile import ProfileError, default_profile_path, load_profile_data, parse_profile
from ocu.sim import ur, xarm
from ocu.sim.extended import DEFAULT_DRAIN_PERCENT_PER_S, DEFAULT_STATUS_HZ
from ocu.sim.faults import FaultConfig
from ocu.sim.rangefinder import (
    DEFAULT_BEAMS,
    DEFAULT_NOISE_M,
    DEFAULT_RANGE_MAX_M,
    DEFAULT_SCAN_HZ,
    RangeSensorConfig,
)
from ocu.sim.scramble import scramble_profile_data, write_truth
from ocu.sim.simulator import RobotSimulator
from ocu.sim.video import MAX_FRAME_SIDE_PX, MIN_FRAME_SIDE_PX

log = logging.getLogger("ocu.sim")

LOG_LEVELS = ("DEBUG", "INFO", "WARNING", "ERROR")
_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
_HANDLED_SIGNALS = (*_STOP_SIGNALS, signal.SIGUSR1, signal.SIGUSR2)
STDIN_FD = 0
# How long the main thread waits for a signal before looking at those Python's handler
# noted: numpy's and OpenCV's threads start at import, before the signals are blocked, and a
# signal the kernel hands to one of them reaches main through the handler, not sigtimedwait.
SIGNAL_POLL_S = 0.2


def _number(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"not a finite number: {text!r}")
    return value


def _probability(text: str) -> float:
    value = _number(text)
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"must be a probability in [0, 1], got {text}")
    return value


def _non_negative(text: str) -> float:
    value = _number(text)
    if value < 0.0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return value


def _positive(text: str) -> float:
    value = _number(text)
    if value <= 0.0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return value


def _percent(text: str) -> float:
    value = _number(text)
    if not 0.0 <= value <= 100.0:
        raise argparse.ArgumentTypeError(f"must be a percentage in [0, 100], got {text}")
    return value


def _port(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a port number: {text!r}") from None
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"port must be in [0, 65535], got {value}")
    return value


def _frame_size(text: str) -> tuple[int, int]:
    parts = text.lower().split("x")
    if len(parts) != 2 or not all(part.strip().isdigit() for part in parts):
        raise argparse.ArgumentTypeError(f"size must look like 320x240, got {text!r}")
    width_px, height_px = (int(part) for part in parts)
    for side in (width_px, height_px):
        if not MIN_FRAME_SIDE_PX <= side <= MAX_FRAME_SIDE_PX:
            raise argparse.ArgumentTypeError(
                f"each side must be in [{MIN_FRAME_SIDE_PX}, {MAX_FRAME_SIDE_PX}], got {text}"
            )
    return width_px, height_px


def _raw_position(text: str) -> tuple[str, int]:
    joint, sep, raw_text = text.partition("=")
    try:
        raw = int(raw_text, 0)
    except ValueError:
        raw = -1
    if not sep or not joint or not 0 <= raw <= 0xFFFFFFFF:
        raise argparse.ArgumentTypeError(
            f"use JOINT=RAW with RAW a u32 (0x.. allowed), got {text!r}"
        )
    return joint, raw


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ocu-sim."""
    parser = argparse.ArgumentParser(
        prog="ocu-sim",
        description="Simulated Servosila Engineer robot server (UDP). "
        "SIGUSR1 cuts the link, SIGUSR2 restores it.",
    )
    parser.add_argument("--host", default="127.0.0.1", help="address to bind (default %(default)s)")
    parser.add_argument(
        "--port", type=_port, default=None, help="UDP port (default: the profile's; 0 = any free)"
    )
    parser.add_argument("--profile", metavar="FILE", default=None, help="robot profile TOML")
    parser.add_argument(
        "--telemetry-hz",
        type=_positive,
        default=None,
        help="telemetry packets per second (default: the profile's)",
    )
    parser.add_argument(
        "--video-fps", type=_non_negative, default=10.0, help="video frames per second, 0 = off"
    )
    parser.add_argument(
        "--video-size", type=_frame_size, default=(320, 240), metavar="WxH", help="frame size"
    )
    parser.add_argument("--loss", type=_probability, default=0.0, help="drop probability")
    parser.add_argument("--latency-ms", type=_non_negative, default=0.0, help="fixed delay")
    parser.add_argument(
        "--jitter-ms", type=_non_negative, default=0.0, help="extra uniform delay 0..jitter"
    )
    parser.add_argument(
        "--duplicate", type=_probability, default=0.0, help="probability to send a datagram twice"
    )
    parser.add_argument(
        "--noise-deg",
        type=_non_negative,
        default=0.0,
        help="uniform noise of ± this many degrees on every reported joint position",
    )
    parser.add_argument(
        "--raw-position",
        action="append",
        default=[],
        type=_raw_position,
        metavar="JOINT=RAW",
        help="a broken encoder: JOINT always reports this raw u32 position (e.g. shoulder=0)",
    )
    parser.add_argument("--seed", type=int, default=None, help="seed of the fault decisions")
    parser.add_argument(
        "--scramble",
        type=int,
        default=None,
        metavar="SEED",
        help="play an unknown robot: the profile's axes shuffled, directions flipped, new "
        "joint scales, ticks per radian and zero offsets drawn from SEED (docs/calibration.md)",
    )
    parser.add_argument(
        "--scramble-ids",
        action="store_true",
        help="with --scramble: also shuffle the device IDs of the motors with a position",
    )
    parser.add_argument(
        "--scramble-out",
        metavar="FILE",
        default=None,
        help="with --scramble: write the hidden truth (the scrambled profile) to FILE",
    )
    parser.add_argument(
        "--extended",
        action="store_true",
        help="also speak ocu's protocol extension: four cameras, status, battery "
        "(docs/protocol.md)",
    )
    parser.add_argument(
        "--status-hz",
        type=_positive,
        default=DEFAULT_STATUS_HZ,
        help="extension status packets per second (default %(default)s)",
    )
    parser.add_argument(
        "--battery-percent", type=_percent, default=100.0, help="starting charge (extension)"
    )
    parser.add_argument(
        "--battery-drain",
        type=_non_negative,
        default=DEFAULT_DRAIN_PERCENT_PER_S,
        metavar="PERCENT_PER_S",
        help="battery drain at rest, in percent per second (default %(default)s)",
    )
    parser.add_argument(
        "--world",
        metavar="FILE",
        default=None,
        help="walls and boxes to drive among (TOML in metres, docs/navigation.md); "
        f"'{DEFAULT_WORLD}' is the shipped room. Without it: an open plane",
    )
    parser.add_argument(
        "--turn-slip",
        type=_probability,
        default=0.0,
        metavar="FRACTION",
        help="the tracks skid in turns: the chassis turns this fraction less than its belts "
        "say (default 0); odometry from track speeds then drifts, an IMU heading does not",
    )
    parser.add_argument(
        "--scan-hz",
        type=_non_negative,
        default=DEFAULT_SCAN_HZ,
        help="range scans per second sent over the extension (default %(default)s; 0 = the "
        "robot has no range sensor)",
    )
    parser.add_argument(
        "--scan-beams", type=int, default=DEFAULT_BEAMS, help="beams per scan over 360 degrees"
    )
    parser.add_argument(
        "--scan-noise-m",
        type=_non_negative,
        default=DEFAULT_NOISE_M,
        help="range noise, 1 sigma (default %(default)s m)",
    )
    parser.add_argument(
        "--exit-with-parent",
        action="store_true",
        help="stop cleanly when standard input reaches its end: started with stdin a pipe "
        "from the parent, the simulator then exits when the parent dies, even by SIGKILL "
        "(ocu and ocu-ros start their built-in simulator this way)",
    )
    parser.add_argument(
        "--log-level", type=str.upper, choices=LOG_LEVELS, default="INFO", help="logging level"
    )
    return parser


def _stop_at_end_of_stdin() -> None:
    """Read stdin to its end, then SIGTERM the main thread so its wait runs the shutdown."""
    try:
        while os.read(STDIN_FD, 4096):
            pass
    except OSError:
        pass  # no usable stdin: as good as closed
    log.info("standard input closed (parent gone)")
    # To the main thread itself (blocked there, taken by its sigtimedwait): a signal to the
    # process could go to a library thread that does not block it and end the process unclean.
    signal.pthread_kill(threading.main_thread().ident or 0, signal.SIGTERM)


def _wait_for_signal(noted: list[int]) -> int:
    """The next handled signal: taken where it is pending, or noted by the handler."""
    while True:
        info = signal.sigtimedwait(_HANDLED_SIGNALS, SIGNAL_POLL_S)
        if info is not None:
            return info.si_signo
        if noted:
            return noted.pop(0)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the simulator until SIGINT or SIGTERM; returns the exit code."""
    if ur.is_ur_profile(sys.argv[1:] if argv is None else argv):
        return ur.main(argv)  # `ocu-sim --profile ur5e`: the UR controller (docs/ur.md)
    if xarm.is_xarm_profile(sys.argv[1:] if argv is None else argv):
        return xarm.main(argv)  # `ocu-sim --profile xarm1s`: the xArm's board (docs/xarm.md)
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.scramble is None and (args.scramble_ids or args.scramble_out):
        parser.error("--scramble-ids and --scramble-out need --scramble SEED")
    try:
        data = load_profile_data(args.profile)
        if args.scramble is not None:
            data = scramble_profile_data(data, args.scramble, ids=args.scramble_ids)
        profile = parse_profile(data, source=str(args.profile or default_profile_path()))
        if args.scramble_out is not None:
            write_truth(args.scramble_out, data, args.scramble, args.scramble_ids)
    except ProfileError as err:
        parser.error(str(err))
    except OSError as err:
        parser.error(f"--scramble-out: {err}")
    logging.basicConfig(
        level=args.log_level, format="%(asctime)s %(levelname)s %(name)s: %(message)s"
    )
    faults = FaultConfig(
        loss=args.loss,
        latency_ms=args.latency_ms,
        jitter_ms=args.jitter_ms,
        duplicate=args.duplicate,
    )
    port = profile.link.port if args.port is None else args.port
    world = None
    if args.world is not None:
        try:
            world = load_world(args.world)
        except WorldError as err:
            parser.error(f"--world: {err}")
    range_sensor = None
    if args.scan_hz > 0.0:
        try:
            range_sensor = RangeSensorConfig(
                beams=args.scan_beams,
                scan_hz=args.scan_hz,
                range_max_m=DEFAULT_RANGE_MAX_M,
                noise_m=args.scan_noise_m,
            )
        except ValueError as err:
            parser.error(f"range sensor: {err}")
    # Block the handled signals before the loop thread exists so it inherits the mask and the
    # main thread alone takes them, synchronously, with sigtimedwait. Threads that libraries
    # started at import do not block them: a signal given to one runs this handler (never
    # the default action, which would kill the simulator without its shutdown).
    noted: list[int] = []
    previous_handlers = {
        signum: signal.signal(signum, lambda signum, _frame: noted.append(signum))
        for signum in _HANDLED_SIGNALS
    }
    previous_mask = signal.pthread_sigmask(signal.SIG_BLOCK, _HANDLED_SIGNALS)
    try:
        if args.exit_with_parent:
            # Started under the mask too (its own reads need no signal).
            threading.Thread(
                target=_stop_at_end_of_stdin, name="ocu-sim-stdin", daemon=True
            ).start()
        try:
            simulator = RobotSimulator(
                profile,
                args.host,
                port,
                telemetry_hz=args.telemetry_hz,
                video_fps=args.video_fps,
                video_size=args.video_size,
                faults=faults,
                seed=args.seed,
                extended=args.extended,
                status_hz=args.status_hz,
                battery_percent=args.battery_percent,
                battery_drain_percent_per_s=args.battery_drain,
                noise_deg=args.noise_deg,
                world=world,
                range_sensor=range_sensor,
                turn_slip=min(args.turn_slip, 0.99),
            )
        except TransportError as err:
            print(f"ocu-sim: cannot listen: {err}", file=sys.stderr)
            return 1
        except ValueError as err:
            parser.error(str(err))
        for joint, raw in args.raw_position:
            try:
                simulator.set_raw_position(joint, raw)
            except ValueError as err:
                simulator.stop()
                parser.error(f"--raw-position: {err}")
        with simulator:
            host, bound_port = simulator.address
            print(f"ocu-sim listening on {host}:{bound_port}", flush=True)
            while True:
                signum = _wait_for_signal(noted)
                if signum == signal.SIGUSR1:
                    simulator.cut_link()
                elif signum == signal.SIGUSR2:
                    simulator.restore_link()
                else:
                    log.info("%s received, stopping", signal.Signals(signum).name)
                    break
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous_mask)
        for signum, handler in previous_handlers.items():
            signal.signal(signum, handler)
    return 0
