"""`ocu screenshot --window OUT.png`: the whole console on the built-in simulator, no display.

Qt runs on its offscreen platform and the 3D dock renders through OSMesa. The console
connects to a simulator child process (vendor protocol unless `--sim-arg=--extended`),
optionally moves joints to `--joints` targets under position control, and after `--seconds`
the window is grabbed into a PNG. The window layout is the default one (settings in a
temporary directory), never the user's.
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path

from ocu.console.model import ConsoleModel
from ocu.control.position import PositionError
from ocu.profile import ProfileError, RobotProfile, load_profile
from ocu.render.platform import configure_gl_platform
from ocu.render.screenshot import ScreenshotError, parse_size

log = logging.getLogger("ocu.screenshot")

SETTLE_MS = 500  # telemetry flowing and the window active before the targets are set


def build_parser() -> argparse.ArgumentParser:
    """The command line of `ocu screenshot --window`."""
    parser = argparse.ArgumentParser(
        prog="ocu screenshot --window",
        description="Render the whole console (all docks, the 3D view via OSMesa) against "
        "the built-in simulator after a few seconds, with no display.",
    )
    parser.add_argument("out", type=Path, help="PNG file to write")
    parser.add_argument("--window", action="store_true", required=True, help="the console")
    parser.add_argument(
        "--seconds", type=float, default=3.0, help="run this long before the picture (3)"
    )
    parser.add_argument("--size", default="1600x1000", help="window size WxH (1600x1000)")
    parser.add_argument(
        "--joints",
        nargs="+",
        default=[],
        metavar="NAME=DEG",
        help="position targets in degrees, set once telemetry flows (shows motion)",
    )
    parser.add_argument(
        "--sim-arg",
        action="append",
        default=[],
        metavar="ARG",
        help="extra argument for the simulator, e.g. --sim-arg=--extended",
    )
    parser.add_argument("--profile", metavar="FILE", help="robot profile (TOML)")
    return parser


def parse_targets(items: Sequence[str], profile: RobotProfile) -> dict[str, float]:
    """`name=deg` pairs to radians for joints with position feedback."""
    joints = [motor.name for motor in profile.positioned_motors]
    targets: dict[str, float] = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or name not in joints:
            raise ScreenshotError(
                f"--joints {item!r}: expected NAME=DEG with NAME one of {', '.join(joints)}"
            )
        try:
            degrees = float(value)
        except ValueError:
            raise ScreenshotError(f"--joints {item!r}: {value!r} is not a number") from None
        if not math.isfinite(degrees):
            raise ScreenshotError(f"--joints {item!r}: angle must be finite")
        targets[name] = math.radians(degrees)
    try:
        ConsoleModel(profile).set_targets(targets)  # refused here rather than in the window
    except PositionError as err:
        raise ScreenshotError(f"--joints: {err}") from err
    return targets


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; argv are the arguments after `screenshot`. Returns the exit status."""
    args = build_parser().parse_args(argv)
    try:
        profile = load_profile(args.profile)
        size = parse_size(args.size)
        targets = parse_targets(args.joints, profile)
        if not (math.isfinite(args.seconds) and args.seconds >= 0.0):
            raise ScreenshotError(f"--seconds {args.seconds!r}: expected a time >= 0")
    except (ScreenshotError, ProfileError) as err:
        print(f"ocu screenshot: {err}", file=sys.stderr)
        return 1
    # Before Qt and PyOpenGL are imported: no display, the 3D view through OSMesa.
    os.environ["QT_QPA_PLATFORM"] = "offscreen"
    configure_gl_platform("offscreen")
    logging.basicConfig(level=logging.WARNING, format="%(asctime)s %(name)s %(message)s")
    with tempfile.TemporaryDirectory(prefix="ocu-screenshot-") as config_dir:
        try:
            return _shoot(profile, args, size, targets, Path(config_dir))
        except (ScreenshotError, OSError, RuntimeError) as err:
            print(f"ocu screenshot: {err}", file=sys.stderr)
            return 1


def _shoot(
    profile: RobotProfile,
    args: argparse.Namespace,
    size: tuple[int, int],
    targets: dict[str, float],
    config_dir: Path,
) -> int:
    from PySide6.QtCore import QSettings, QTimer
    from PySide6.QtWidgets import QApplication

    from ocu.link.base import Link
    from ocu.link.live import UdpLink
    from ocu.record.recorder import Recorder
    from ocu.sim.launcher import SimulatorProcess, with_default_world
    from ocu.windows.main_window import MainWindow
    from ocu.windows.teardown import dispose

    app = QApplication.instance() or QApplication(sys.argv[:1])
    assert isinstance(app, QApplication)
    with SimulatorProcess(args.profile, with_default_world(args.sim_arg)) as simulator:
        address = simulator.address

        def make_link() -> Link:
            return UdpLink(profile, address, extension=True)

        settings = QSettings(str(config_dir / "ocu.ini"), QSettings.Format.IniFormat)
        window = MainWindow(
            profile,
            make_link,
            f"simulator {address[0]}:{address[1]}",
            settings,
            recorder=Recorder(profile),  # the Record button shows; nothing is recorded
        )
        saved: list[str] = []
        drawn_through: list[str] = []
        try:
            window.resize(*size)
            window.show()
            window.activateWindow()  # an inactive console halts the model (focus rule)

            def set_targets() -> None:
                if targets:
                    window.model.set_targets(targets)

            def grab() -> None:
                window.model_view.reset_view()  # frame the pose reached
                window.model_view.render_now()
                drawn_through.append(window.model_view.drawn_through)
                picture = window.grab()
                args.out.parent.mkdir(parents=True, exist_ok=True)
                if picture.save(str(args.out), "PNG"):
                    saved.append(str(args.out))
                app.quit()

            QTimer.singleShot(min(SETTLE_MS, int(args.seconds * 1000)), set_targets)
            QTimer.singleShot(int(args.seconds * 1000), grab)
            app.exec()
        finally:
            window.shutdown()
            dispose(window)
    if not saved:
        raise ScreenshotError(f"cannot write {args.out}")
    print(f"wrote {args.out} ({size[0]}x{size[1]}); 3D view drawn through {drawn_through[0]}")
    return 0
