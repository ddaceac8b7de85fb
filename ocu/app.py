"""The `ocu` command: start the console on the built-in simulator or a real robot."""

from __future__ import annotations

import argparse
import logging
import signal
import sys
from collections.abc import Sequence

from ocu.profile import ProfileError, RobotProfile, load_profile

log = logging.getLogger("ocu")


def parse_robot(text: str, default_port: int) -> tuple[str, int]:
    """HOST[:PORT] into an address; argparse-style error on a bad port."""
    host, sep, port_text = text.rpartition(":")
    if not sep:
        return text, default_port
    try:
        port = int(port_text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"bad port in {text!r}") from None
    if not 1 <= port <= 65535 or not host:
        raise argparse.ArgumentTypeError(f"bad address {text!r}: use HOST[:PORT]")
    return host, port


def build_parser() -> argparse.ArgumentParser:
    """Command-line options of `ocu`."""
    parser = argparse.ArgumentParser(
        prog="ocu",
        description="Operator Control Unit for the Servosila Engineer. With no --robot it "
        "starts the built-in simulator on 127.0.0.1 and connects to it.",
        epilog="Subcommands: `ocu screenshot OUT.png [--joints name=deg ...]` renders without "
        "a display.",
    )
    parser.add_argument("--robot", metavar="HOST[:PORT]", help="connect to a robot")
    parser.add_argument("--profile", metavar="FILE", help="robot profile (TOML)")
    parser.add_argument(
        "--sim-arg",
        action="append",
        default=[],
        metavar="ARG",
        help="extra argument for the built-in simulator, e.g. --sim-arg=--loss=0.1",
    )
    parser.add_argument(
        "--quit-after", type=float, metavar="S", help="quit by itself after S seconds"
    )
    parser.add_argument("--log-level", default="INFO")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the `ocu` console script."""
    args_list = list(sys.argv[1:] if argv is None else argv)
    if args_list and args_list[0] == "screenshot":
        from ocu.render.screenshot import main as screenshot_main

        return screenshot_main(args_list[1:])
    parser = build_parser()
    args = parser.parse_args(args_list)
    logging.basicConfig(level=args.log_level.upper(), format="%(asctime)s %(name)s %(message)s")
    try:
        profile = load_profile(args.profile)
    except ProfileError as err:
        parser.error(str(err))
    robot = None
    if args.robot:
        try:
            robot = parse_robot(args.robot, profile.link.port)
        except argparse.ArgumentTypeError as err:
            parser.error(str(err))
    return run_console(profile, robot, args.profile, args.sim_arg, args.quit_after)


def run_console(
    profile: RobotProfile,
    robot: tuple[str, int] | None,
    profile_path: str | None,
    sim_args: list[str],
    quit_after_s: float | None,
) -> int:
    """Start simulator (if no robot), link and window; run the Qt event loop."""
    from PySide6.QtCore import QTimer
    from PySide6.QtWidgets import QApplication

    from ocu.link.core import LinkCore, LinkError
    from ocu.link.qt import LinkThread
    from ocu.sim.launcher import SimulatorProcess, SimulatorProcessError
    from ocu.windows.main_window import MainWindow

    app = QApplication.instance() or QApplication(sys.argv[:1])
    simulator: SimulatorProcess | None = None
    if robot is None:
        try:
            simulator = SimulatorProcess(profile_path, sim_args)
        except SimulatorProcessError as err:
            log.error("%s", err)
            return 1
        robot = simulator.address
        address_text = f"simulator {robot[0]}:{robot[1]}"
    else:
        address_text = f"robot {robot[0]}:{robot[1]}"
    try:
        try:
            core = LinkCore(profile, robot)
        except LinkError as err:
            log.error("%s", err)
            return 1
        link = LinkThread(core)
        window = MainWindow(profile, link, address_text)
        app.aboutToQuit.connect(link.shutdown)
        # Python handles SIGINT/SIGTERM only when the interpreter runs: a short timer lets it,
        # and the handler quits Qt so shutdown sends zeros before the process ends.
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: app.quit())
        pulse = QTimer()
        pulse.start(200)
        pulse.timeout.connect(lambda: None)
        if quit_after_s is not None:
            QTimer.singleShot(int(quit_after_s * 1000), app.quit)
        window.show()
        link.start_link()
        code = app.exec()
        link.shutdown()
        return code
    finally:
        if simulator is not None:
            simulator.stop()


if __name__ == "__main__":
    sys.exit(main())
