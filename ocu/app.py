"""The `ocu` command: start the console on the built-in simulator or a real robot.

Also `ocu --record FILE`, `ocu --replay FILE`, `ocu inspect FILE` (docs/recordings.md),
`ocu screenshot [--window] OUT.png` (the model, or the whole console, without a display) and
`ocu probe` / `ocu calibrate` (first contact with a robot: docs/calibration.md).
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from ocu.console.poses import CONFIG_DIR_ENV, default_config_dir
from ocu.consoles import run_arm_window, run_console, run_replay, run_ur_console
from ocu.core.manager import DEFAULT_RATE_HZ as DEFAULT_CONTROL_HZ
from ocu.core.manager import MAX_RATE_HZ as MAX_CONTROL_HZ
from ocu.core.manager import MIN_RATE_HZ as MIN_CONTROL_HZ
from ocu.core.manager import control_rate
from ocu.lifecycle import STOP
from ocu.live.options import (
    LiveError,
    add_live_options,
    start_live,
)
from ocu.priority import (
    DEFAULT_NICE,
    NICE_ENV,
    nice_from_env,
    nice_value,
    raise_priority,
)
from ocu.profile import ProfileError, RobotProfile, load_profile
from ocu.profile.ur import UrArmProfile
from ocu.profile.ur_robot import load_ur_arm, ur_robot_profile
from ocu.profile.xarm import load_xarm_arm
from ocu.profile.xarm_robot import xarm_robot_profile
from ocu.windows.settings_file import SETTINGS_FILE

if TYPE_CHECKING:
    from ocu.gamepad.mapping import PadMapping
    from ocu.hotkeys import KeyMap
    from ocu.live.server import LiveServer
    from ocu.windows.cameras import LocalCameras

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
        epilog="Subcommands: `ocu screenshot OUT.png [--joints name=deg ...]` renders the model "
        "without a display; `ocu screenshot --window OUT.png [--seconds S]` the whole console "
        "on the built-in simulator; `ocu urdf-check FOLDER` loads every URDF in a folder and "
        "reports what loaded, warned or failed; `ocu inspect FILE.mcap` summarises a recording; "
        "`ocu probe --robot HOST[:PORT]` checks what a robot sends against the profile; "
        "`ocu calibrate --robot HOST[:PORT] --out PROFILE.toml [--yes]` measures the robot "
        "and writes a profile (docs/calibration.md).",
    )
    parser.add_argument("--robot", metavar="HOST[:PORT]", help="connect to a robot")
    files = parser.add_mutually_exclusive_group()
    files.add_argument(
        "--record",
        metavar="FILE.mcap",
        type=Path,
        help="record the session from the start (the file is overwritten)",
    )
    files.add_argument(
        "--replay",
        metavar="FILE.mcap",
        type=Path,
        help="replay a recording in the console: no simulator, no robot, commands disabled",
    )
    parser.add_argument("--profile", metavar="FILE", help="robot profile (TOML)")
    parser.add_argument(
        "--sim-arg",
        action="append",
        default=[],
        metavar="ARG",
        help="extra argument for the built-in simulator, e.g. --sim-arg=--loss=0.1; "
        "--sim-arg=--extended makes it speak the protocol extension (four cameras, battery, "
        "headlight, roll/pitch, IMU heading, range scans); the simulator runs in the shipped "
        "room unless --sim-arg=--world=FILE names another world",
    )
    parser.add_argument(
        "--quit-after", type=float, metavar="S", help="quit by itself after S seconds"
    )
    parser.add_argument(
        "--config-dir",
        metavar="DIR",
        type=Path,
        help=f"where the window layout ({SETTINGS_FILE}), the hotkey and gamepad overrides "
        f"(hotkeys.toml, gamepad.toml) and the pads' calibration live; default "
        f"${CONFIG_DIR_ENV} or ~/.config/ocu",
    )
    parser.add_argument(
        "--keys", metavar="FILE", type=Path, help="hotkey map merged over the default one"
    )
    parser.add_argument(
        "--pad-map", metavar="FILE", type=Path, help="gamepad mapping merged over the default one"
    )
    parser.add_argument("--no-gamepad", action="store_true", help="do not read game controllers")
    parser.add_argument(
        "--control-hz",
        type=control_rate,
        default=DEFAULT_CONTROL_HZ,
        metavar="HZ",
        help=f"the control thread's rate (default {DEFAULT_CONTROL_HZ:g}; "
        f"{MIN_CONTROL_HZ:g}-{MAX_CONTROL_HZ:g})",
    )
    parser.add_argument(
        "--nice",
        type=nice_value,
        default=None,
        metavar="N",
        help=f"run the console at this nice value where allowed (default ${NICE_ENV} or "
        f"{DEFAULT_NICE}, ahead of batch jobs; 0 keeps the default priority; needs "
        "CAP_SYS_NICE or an RLIMIT_NICE allowance, else the console says what it got)",
    )
    parser.add_argument(
        "--camera",
        action="append",
        default=[],
        metavar="DEVICE",
        help="a camera of this machine in the Video dock, for any robot: /dev/video0, an "
        "index (0), a video file, or `scene` (the xArm simulator's gripper camera); on the "
        "xArm the first rides on the gripper and click-to-track moves the arm (docs/xarm.md)",
    )
    where = parser.add_mutually_exclusive_group()
    where.add_argument(
        "--core-process",
        action="store_true",
        help="run the control core (model, control thread, link, X key reader, pad) in a "
        "process of its own, out of the GUI's interpreter: the default for the Engineer's, "
        "a UR's and the xArm's consoles; refused with --replay, --live or --camera "
        "(docs/core-process.md)",
    )
    where.add_argument(
        "--in-process",
        action="store_true",
        help="run the control core on a thread of the window's own process (the default "
        "with --replay, --live or --camera)",
    )
    parser.add_argument("--log-level", default="INFO")
    add_live_options(parser)
    return parser


def refuse_file(message: str) -> int:
    """Report a bad profile or key map in one line (the usage is not the problem); exit 2."""
    print(f"ocu: error: {message}", file=sys.stderr)
    return 2


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the `ocu` console script."""
    args_list = list(sys.argv[1:] if argv is None else argv)
    if args_list and args_list[0] == "screenshot":
        if "--window" in args_list[1:]:
            from ocu.windows.screenshot import main as window_screenshot_main

            return window_screenshot_main(args_list[1:])
        from ocu.render.screenshot import main as screenshot_main

        return screenshot_main(args_list[1:])
    if args_list and args_list[0] == "urdf-check":
        from ocu.model.check import main as urdf_check_main

        return urdf_check_main(args_list[1:])
    if args_list and args_list[0] == "inspect":
        from ocu.record.inspect import main as inspect_main

        return inspect_main(args_list[1:])
    if args_list and args_list[0] == "probe":
        from ocu.calibrate.cli import probe_main

        return probe_main(args_list[1:])
    if args_list and args_list[0] == "calibrate":
        from ocu.calibrate.cli import calibrate_main

        return calibrate_main(args_list[1:])
    parser = build_parser()
    args = parser.parse_args(args_list)
    if args.replay is not None and (args.robot or args.sim_arg):
        parser.error("--replay plays a file: --robot and --sim-arg do not apply")
    if args.replay is not None and args.live_control:
        parser.error("--replay plays a file: nothing to drive with --live-control")
    logging.basicConfig(level=args.log_level.upper(), format="%(asctime)s %(name)s %(message)s")
    try:
        nice = nice_from_env() if args.nice is None else args.nice
    except ValueError as err:
        parser.error(str(err))
    try:
        ur_arm, xarm = load_ur_arm(args.profile), load_xarm_arm(args.profile)
        if xarm is not None:
            profile = xarm_robot_profile(xarm)
        else:
            profile = ur_robot_profile(ur_arm) if ur_arm is not None else load_profile(args.profile)
    except ProfileError as err:
        return refuse_file(str(err))
    if ur_arm is not None and args.sim_arg:
        parser.error("--sim-arg is not available for a UR arm yet (docs/ur.md)")
    if xarm is not None:
        for given, option in ((args.sim_arg, "--sim-arg"), (args.live, "--live")):
            if given:
                parser.error(f"{option} is not available for the xArm yet (docs/xarm.md)")
    from ocu.video.capture import CameraError
    from ocu.windows.cameras import LocalCameras, add_cameras

    if args.camera and args.replay is not None:
        parser.error("--replay plays a file: --camera does not apply")
    # The cameras of this machine come after the robot's (ocu.windows.cameras).
    profile = add_cameras(profile, args.camera, tool_link="tool0" if xarm is not None else None)
    if args.replay is not None:
        from ocu.record.ur_replay import recorded_profile

        profile = recorded_profile(args.replay, profile)  # a UR's keys for a UR's recording
    in_process_only = bool(args.replay or args.live or args.camera)
    if args.core_process and in_process_only:
        return refuse_file(
            "--core-process runs the Engineer's, a UR's and the xArm's consoles, not yet "
            "with --replay, --live or --camera (docs/core-process.md)"
        )
    # The control core runs in a process of its own unless asked otherwise or not done yet.
    args.core_process = not args.in_process and not in_process_only
    robot = None
    if args.robot and ur_arm is None and xarm is None:
        try:
            robot = parse_robot(args.robot, profile.link.port)
        except argparse.ArgumentTypeError as err:
            parser.error(str(err))
    from ocu.hotkeys import USER_KEY_MAP_NAME, KeyMapError, load_key_map

    config_dir = args.config_dir if args.config_dir is not None else default_config_dir()
    from ocu.windows.settings_file import config_dir_problem

    config_problem = config_dir_problem(config_dir)
    if config_problem is not None:
        return refuse_file(config_problem)
    override = args.keys if args.keys is not None else config_dir / USER_KEY_MAP_NAME
    if args.keys is not None and not args.keys.exists():
        parser.error(f"--keys: {args.keys} does not exist")
    try:
        key_map = load_key_map(profile, override)
    except KeyMapError as err:
        return refuse_file(str(err))
    from ocu.gamepad.mapping import USER_PAD_MAP_NAME, PadMappingError, load_pad_mapping

    if args.pad_map is not None and not args.pad_map.exists():
        parser.error(f"--pad-map: {args.pad_map} does not exist")
    pad_override = args.pad_map if args.pad_map is not None else config_dir / USER_PAD_MAP_NAME
    try:
        pad_mapping = load_pad_mapping(profile, pad_override)
    except PadMappingError as err:
        return refuse_file(str(err))
    try:
        live = start_live(profile, args.live, args.live_token, args.live_control)  # docs/live.md
    except LiveError as err:
        return refuse_file(str(err))
    # From here on a stop signal quits in order, also one that comes while the window is
    # being built (the link may already be running then): see StopSignals.
    STOP.install()
    # Before Qt, the link or the control core start a thread: threads inherit it.
    log.info("scheduling priority: %s", raise_priority(nice).text)
    if xarm is not None and args.replay is None:
        from ocu.control.reach_tracking import ServoModel
        from ocu.core_process import CoreSpec
        from ocu.hardware.xarm import XARM_CAPABILITIES, ConsoleLinks
        from ocu.record.errors import RecordingError
        from ocu.record.recorder import Recorder
        from ocu.windows.cameras import SCENE, SceneLinks

        recorder = Recorder(profile)
        try:
            if args.record is not None:
                recorder.start(args.record)
            scene = SCENE in args.camera and args.robot is None
            links = SceneLinks(xarm, profile) if scene else ConsoleLinks(xarm, profile, args.robot)
        except (OSError, RecordingError) as err:
            log.error("%s", err)
            recorder.stop()
            return 1
        servo = ServoModel(xarm.servo.damping_ratio, xarm.servo.natural_frequency_rad_s)
        try:
            cameras = LocalCameras(
                profile, args.camera, scene=links if isinstance(links, SceneLinks) else None,
                servo=servo,
            )  # fmt: skip
        except CameraError as err:
            links.close()
            recorder.stop()
            return refuse_file(str(err))
        try:
            return run_arm_window(
                profile,
                (links.make_link, links.hardware_for, XARM_CAPABILITIES),
                links.where,
                args.quit_after,
                config_dir=config_dir,
                key_map=key_map,
                pad_mapping=None if args.no_gamepad else pad_mapping,
                control_hz=args.control_hz,
                recorder=recorder,
                cameras=cameras,
                core=CoreSpec(profile, "xarm", links.path, options={"arm": xarm})
                if args.core_process
                else None,
            )
        finally:
            cameras.stop()
            recorder.stop()  # after the window's shutdown: the link's closing stop move in it
            links.close()
    try:
        cameras = LocalCameras(profile, args.camera)
    except CameraError as err:
        return refuse_file(str(err))
    with contextlib.ExitStack() as stack:
        stack.callback(cameras.stop)
        return run_other(
            args, profile, (ur_arm, robot), config_dir, (key_map, pad_mapping), live=live,
            cameras=cameras,
        )  # fmt: skip


def run_other(
    args: argparse.Namespace,
    profile: RobotProfile,
    robots: tuple[UrArmProfile | None, tuple[str, int] | None],
    config_dir: Path,
    maps: tuple[KeyMap, PadMapping],
    *,
    live: LiveServer | None,
    cameras: LocalCameras,
) -> int:
    """The console on a UR arm, a replay or the Engineer (main()'s last part)."""
    ur_arm, robot = robots
    key_map, pad_mapping = maps
    if ur_arm is not None and args.replay is None:
        return run_ur_console(
            ur_arm,
            profile,
            args.robot,
            args.quit_after,
            config_dir=config_dir,
            key_map=key_map,
            record_path=args.record,
            pad_mapping=None if args.no_gamepad else pad_mapping,
            control_hz=args.control_hz,
            live=live,
            cameras=cameras,
            core_process=args.core_process,
        )
    if args.replay is not None:
        return run_replay(
            profile,
            args.replay,
            args.quit_after,
            config_dir=config_dir,
            key_map=key_map,
            control_hz=args.control_hz,
            live=live,
        )
    return run_console(
        profile,
        robot,
        args.profile,
        args.sim_arg,
        args.quit_after,
        config_dir=config_dir,
        key_map=key_map,
        record_path=args.record,
        pad_mapping=None if args.no_gamepad else pad_mapping,
        control_hz=args.control_hz,
        live=live,
        cameras=cameras,
        core_process=args.core_process,
    )


if __name__ == "__main__":
    sys.exit(main())
