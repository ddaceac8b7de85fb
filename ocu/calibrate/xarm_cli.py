"""`ocu calibrate --profile xarm1s --robot DEVICE --out FILE`: the xArm's calibration on the
command line (ocu.calibrate.xarm; docs/calibration.md, "An xArm 1S").

The options are `ocu calibrate`'s: `--robot` is the serial device, `--answers` a TOML file
with an `[xarm]` table, `--on-stand` no deadman; `--yes` is refused (the zero pose and the
directions need a person). Exit status 0 when the profile was written, 1 when the
calibration was refused or stopped (nothing written), 2 for bad arguments.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TextIO

from ocu.calibrate.guard import Deadman, OnStand, StopSignal
from ocu.calibrate.operator import AnswersError, AnswersOperator, TerminalOperator
from ocu.calibrate.xarm import (
    XarmCalibrationResult,
    XarmCalibrator,
    XarmOperator,
    check_out_file,
    raw_arm,
    summary,
    write_xarm_profile,
)
from ocu.link.xarm import XarmLink
from ocu.profile.keys import ProfileError
from ocu.profile.xarm import (
    XarmProfile,
    is_xarm_file,
    load_xarm_profile,
    shipped_xarm_profiles,
)


def is_xarm_profile_arg(profile: str | None) -> bool:
    """Whether `--profile` names an xArm profile: a shipped name, or a file in the xArm
    format (one this wrote, too)."""
    return profile is not None and (profile in shipped_xarm_profiles() or is_xarm_file(profile))


def calibrate_xarm(
    parser: argparse.ArgumentParser,
    args: argparse.Namespace,
    stdin: TextIO | None,
    out: TextIO,
    stop: StopSignal,
) -> int:
    """The xArm's calibration with `ocu calibrate`'s parsed arguments."""
    from ocu.calibrate.cli import HeldEnterOperator, TerminalDeadman  # cli imports this module

    def say(text: str) -> None:
        print(text, file=out, flush=True)

    if args.yes:
        parser.error("--yes: an xArm's zero pose and directions need a person (use --answers)")
    if args.telemetry_hz is not None:
        parser.error("--telemetry-hz does not apply to an xArm")
    if not args.out.parent.is_dir():
        parser.error(f"--out: no directory {args.out.parent}")
    try:
        arm = load_xarm_profile(args.profile)
        check_out_file(args.out)
        operator: XarmOperator = (
            AnswersOperator.from_file(args.answers, say)
            if args.answers
            else TerminalOperator(stdin, out)
        )
    except (ProfileError, AnswersError) as err:
        print(f"ocu calibrate: error: {err}", file=sys.stderr)
        return 2
    if stop.stopped:
        say(f"stopped: {stop.reason}; nothing written")
        return 1
    deadman: Deadman = OnStand()
    if not args.on_stand or isinstance(operator, TerminalOperator):
        terminal = TerminalDeadman(stdin or sys.stdin, stop)
        if isinstance(operator, TerminalOperator):
            operator = HeldEnterOperator(operator, terminal)
        if not args.on_stand:
            deadman = terminal
            say("Hold Enter while the arm may move; let go to stop it. Ctrl-C stops everything.")
    link = XarmLink(raw_arm(arm), args.robot)
    calibrator = XarmCalibrator(link, arm, operator, deadman=deadman, stop=stop)
    try:
        result = calibrator.run()
    finally:
        link.shutdown()  # the stop move last
    if stop.stopped and result.aborted is None:
        result.aborted = stop.reason
    return _finish(args.out, arm, result, args.robot, say)


def _finish(
    path: Path,
    arm: XarmProfile,
    result: XarmCalibrationResult,
    robot: str,
    say: Callable[[str], None],
) -> int:
    if result.aborted is not None:
        say(f"stopped: {result.aborted}; nothing written")
        return 1
    try:
        write_xarm_profile(path, arm, result, robot=robot)
    except (ProfileError, OSError) as err:
        print(f"ocu calibrate: cannot write {path}: {err}", file=sys.stderr)
        return 1
    for joint, text in summary(result, arm).items():
        say(f"{joint}: {text}")
    say(f"wrote {path}; use it with `ocu --profile {path} --robot {robot}`")
    return 0
