"""Who answers the calibration's questions: nobody (--yes), a file (tests), a terminal, a dock.

The calibrator asks through the `Operator` protocol and never knows which one answers. The
automatic operator (`--yes`) confirms every automatic step, skips the steps that need a
person (the known-angle check, limits, drive constants) and keeps the profile's device ID
-> joint map. `AnswersOperator` answers from a TOML file (for tests of the guided mode and
for repeating a calibration); `TerminalOperator` asks on a terminal.
"""

from __future__ import annotations

import math
import sys
import tomllib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, TextIO

from ocu.calibrate.guard import CalibrationAbortedError
from ocu.profile import did_you_mean

LINEAR = "linear"
ROTATION = "rotation"
DRIVE_KINDS = (LINEAR, ROTATION)
# The speeds of the drive runs at the profile's constants: above the servos' 0.2 m/s and
# 0.2 rad/s (seed 000 §3.3), different so the least-squares fit means something.
DEFAULT_DRIVE_SPEEDS = {LINEAR: (0.25, 0.3, 0.35), ROTATION: (0.3, 0.4, 0.5)}
DEFAULT_DRIVE_DISTANCE = {LINEAR: 1.15, ROTATION: 2 * math.pi}


class AnswersError(ValueError):
    """An answers file that cannot be read, or holds a bad answer."""


@dataclass(frozen=True)
class DrivePlan:
    """Runs of seed 000 §3.1's procedure: each run covers `distance` (m, or rad for the
    rotation) at one speed (at the profile's constant); `stop_after_s`, when given, ends
    each run after that long (an answers file) instead of the operator releasing the key."""

    kind: str
    distance: float
    speeds: tuple[float, ...]
    stop_after_s: tuple[float, ...] | None = None


class Operator(Protocol):
    """The person (or stand-in) at the console during a calibration."""

    @property
    def guided(self) -> bool:
        """Whether a person answers: the guided steps run only then."""
        ...

    def say(self, text: str) -> None:
        """Show what is happening."""
        ...

    def confirm(self, step: str, text: str) -> bool:
        """Start a step? False skips it."""
        ...

    def identify_joint(
        self, device_id: int, profile_name: str | None, choices: Sequence[str]
    ) -> str | None:
        """Which joint moved (device `device_id` answered; the profile calls it
        `profile_name`)? None: the profile is right."""
        ...

    def checks_angle(self, joint: str) -> bool:
        """Move the joint through a known angle for the operator to measure?"""
        ...

    def measured_angle(self, joint: str, moved_deg: float) -> float | None:
        """The angle the operator measured after a move the OCU reckons as moved_deg; None
        accepts the OCU's figure."""
        ...

    def wants_limits(self, joint: str) -> bool:
        """Find the joint's hard stops by slow moves?"""
        ...

    def drive_plan(self, kind: str) -> DrivePlan | None:
        """The runs for one drive constant, or None to keep the profile's."""
        ...

    def drive_time(self, kind: str, index: int, commanded_s: float) -> float | None:
        """The time the operator measured for run `index`; None drops the run."""
        ...


class AutoOperator:
    """`ocu calibrate --yes`: the automatic steps only, no questions."""

    guided = False

    def __init__(self, out: Callable[[str], None] | None = None) -> None:
        self._out = out

    def say(self, text: str) -> None:
        """Print progress if asked to."""
        if self._out is not None:
            self._out(text)

    def confirm(self, step: str, text: str) -> bool:
        """Every automatic step runs."""
        return True

    def identify_joint(
        self, device_id: int, profile_name: str | None, choices: Sequence[str]
    ) -> str | None:
        """The profile's device ID -> joint map is kept."""
        return None

    def checks_angle(self, joint: str) -> bool:
        """Needs a person."""
        return False

    def measured_angle(self, joint: str, moved_deg: float) -> float | None:
        """Not asked."""
        return None

    def wants_limits(self, joint: str) -> bool:
        """Limits need a person."""
        return False

    def drive_plan(self, kind: str) -> DrivePlan | None:
        """Drive constants need a person."""
        return None

    def drive_time(self, kind: str, index: int, commanded_s: float) -> float | None:
        """Not asked."""
        return None

    def zero_pose_ready(self, text: str) -> bool:
        """An xArm's zero pose needs a person: not confirmed."""
        self.say(f"{text} Nobody to confirm it.")
        return False

    def moved_positive(self, joint: str, positive: str) -> bool:
        """An xArm's direction needs a person."""
        raise CalibrationAbortedError(f"nobody to say whether the {joint} moved")


ANSWER_KEYS = ("skip", "joints", "angles", "limits", "drive", "xarm")
XARM_KEYS = ("zero_pose", "directions")
DRIVE_KEYS = ("distance", "speeds", "times_s")


class AnswersOperator(AutoOperator):
    """The guided mode with its answers from a TOML file (docs/calibration.md):

    ```toml
    skip = ["known_angle"]            # steps not to run
    [joints]                          # device ID -> the joint that really moved
    5 = "elbow"
    [angles]                          # joint -> the angle measured after the check move
    shoulder = 8.1
    limits = ["gripper"]              # joints whose hard stops are searched
    [drive.linear]                    # runs of seed 000 §3.1
    distance = 1.15
    speeds = [0.25, 0.3, 0.35]
    times_s = [4.6, 3.8, 3.3]
    ```

    An xArm's (docs/calibration.md, "An xArm 1S"): whether the arm is in its zero pose, and
    per joint whether it moved the positive way (true, false, or "stop": the operator stops):

    ```toml
    [xarm]
    zero_pose = true
    directions = { base = true, elbow = false, shoulder = "stop" }
    ```
    """

    guided = True

    def __init__(self, answers: dict[str, Any], out: Callable[[str], None] | None = None) -> None:
        super().__init__(out)
        unknown = [key for key in answers if key not in ANSWER_KEYS]
        if unknown:
            raise AnswersError(
                "; ".join(
                    f"answers.{k}: unknown key; {did_you_mean(k, ANSWER_KEYS)}" for k in unknown
                )
            )
        self.skip = set(_strings(answers.get("skip", []), "skip"))
        joints = answers.get("joints", {})
        if not isinstance(joints, dict):
            raise AnswersError("answers.joints: a table of device ID = joint name")
        self.joints: dict[int, str] = {}
        for key, name in joints.items():
            if not key.isdigit() or not isinstance(name, str):
                raise AnswersError(f'answers.joints.{key}: device ID = "joint name"')
            self.joints[int(key)] = name
        angles = answers.get("angles", {})
        if not isinstance(angles, dict) or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in angles.values()
        ):
            raise AnswersError("answers.angles: a table of joint = degrees")
        self.angles = {k: float(v) for k, v in angles.items()}
        self.limits = set(_strings(answers.get("limits", []), "limits"))
        self.drive: dict[str, DrivePlan] = {}
        drive = answers.get("drive", {})
        if not isinstance(drive, dict):
            raise AnswersError("answers.drive: tables drive.linear and drive.rotation")
        for kind, table in drive.items():
            if kind not in DRIVE_KINDS or not isinstance(table, dict):
                raise AnswersError(f"answers.drive.{kind}: {did_you_mean(kind, DRIVE_KINDS)}")
            self.drive[kind] = _drive_plan(kind, table)
        self.zero_pose, self.directions = _xarm_answers(answers.get("xarm", {}))

    @classmethod
    def from_file(
        cls, path: str | Path, out: Callable[[str], None] | None = None
    ) -> AnswersOperator:
        """Read an answers file; AnswersError names what is wrong."""
        try:
            data = tomllib.loads(Path(path).read_text(encoding="utf-8"))
        except OSError as err:
            raise AnswersError(f"cannot read answers {path}: {err.strerror}") from err
        except (UnicodeDecodeError, tomllib.TOMLDecodeError) as err:
            raise AnswersError(f"{path}: not a TOML file: {err}") from err
        return cls(data, out)

    def confirm(self, step: str, text: str) -> bool:
        """A step runs unless the file skips it."""
        return step not in self.skip

    def identify_joint(
        self, device_id: int, profile_name: str | None, choices: Sequence[str]
    ) -> str | None:
        """The file's answer for this device, if any."""
        return self.joints.get(device_id)

    def checks_angle(self, joint: str) -> bool:
        """The joints the file has an angle for."""
        return joint in self.angles

    def measured_angle(self, joint: str, moved_deg: float) -> float | None:
        """The file's measured angle for this joint, if any."""
        return self.angles.get(joint)

    def wants_limits(self, joint: str) -> bool:
        """Whether the file lists the joint."""
        return joint in self.limits

    def drive_plan(self, kind: str) -> DrivePlan | None:
        """The file's runs."""
        return self.drive.get(kind)

    def drive_time(self, kind: str, index: int, commanded_s: float) -> float | None:
        """The time the file gives (the run was stopped after it)."""
        plan = self.drive.get(kind)
        if plan is None or plan.stop_after_s is None:
            return None
        return plan.stop_after_s[index]

    def zero_pose_ready(self, text: str) -> bool:
        """The file's `xarm.zero_pose`."""
        self.say(f"{text} (answers: {'ready' if self.zero_pose else 'not ready'})")
        return self.zero_pose

    def moved_positive(self, joint: str, positive: str) -> bool:
        """The file's `xarm.directions` entry for the joint; "stop" stops."""
        answer = self.directions.get(joint)
        if answer is None:
            raise CalibrationAbortedError(f"answers.xarm.directions: no answer for the {joint}")
        if answer == "stop":
            raise CalibrationAbortedError(f"operator: stop (asked whether the {joint} moved)")
        return bool(answer)


def _xarm_answers(table: object) -> tuple[bool, dict[str, bool | str]]:
    where = "answers.xarm"
    if not isinstance(table, dict):
        raise AnswersError(f"{where}: a table with zero_pose and directions")
    unknown = [key for key in table if key not in XARM_KEYS]
    if unknown:
        raise AnswersError(
            f"{where}.{unknown[0]}: unknown key; {did_you_mean(unknown[0], XARM_KEYS)}"
        )
    zero_pose = table.get("zero_pose", False)
    directions = table.get("directions", {})
    if not isinstance(zero_pose, bool):
        raise AnswersError(f"{where}.zero_pose: true or false")
    if not isinstance(directions, dict) or not all(
        isinstance(v, bool) or v == "stop" for v in directions.values()
    ):
        raise AnswersError(f'{where}.directions: a table of joint = true, false or "stop"')
    return zero_pose, dict(directions)


def _strings(value: object, key: str) -> list[str]:
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise AnswersError(f"answers.{key}: a list of names")
    return list(value)


def _drive_plan(kind: str, table: dict[str, Any]) -> DrivePlan:
    where = f"answers.drive.{kind}"
    unknown = [key for key in table if key not in DRIVE_KEYS]
    if unknown:
        raise AnswersError(
            f"{where}.{unknown[0]}: unknown key; {did_you_mean(unknown[0], DRIVE_KEYS)}"
        )
    distance = table.get("distance", DEFAULT_DRIVE_DISTANCE[kind])
    speeds = table.get("speeds", list(DEFAULT_DRIVE_SPEEDS[kind]))
    times = table.get("times_s")
    numbers = [distance, *speeds, *(times or [])]
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0 for v in numbers):
        raise AnswersError(f"{where}: distance, speeds and times_s must be positive numbers")
    if times is None or len(times) != len(speeds):
        raise AnswersError(f"{where}.times_s: one time per speed")
    return DrivePlan(
        kind, float(distance), tuple(float(v) for v in speeds), tuple(float(t) for t in times)
    )


class TerminalOperator(AutoOperator):
    """The guided mode on a terminal: questions on stdout, answers typed on stdin."""

    guided = True

    def __init__(self, stdin: TextIO | None = None, stdout: TextIO | None = None) -> None:
        self._in = stdin or sys.stdin
        self._stdout = stdout or sys.stdout
        super().__init__(self._print)

    def _print(self, text: str) -> None:
        print(text, file=self._stdout, flush=True)

    def _ask(self, question: str) -> str:
        self._stdout.write(f"{question} ")
        self._stdout.flush()
        line = self._in.readline()
        if not line:
            raise EOFError("no more answers on standard input")
        return line.strip()

    def confirm(self, step: str, text: str) -> bool:
        """Run the step? (Enter = yes)."""
        return self._ask(f"{text} Go on? [Y/n]").lower() not in ("n", "no")

    def identify_joint(
        self, device_id: int, profile_name: str | None, choices: Sequence[str]
    ) -> str | None:
        """Which joint moved (Enter: the profile's)."""
        said = profile_name or "no joint"
        while True:
            answer = self._ask(
                f"Device {device_id} moved; the profile says it is the {said}. Which joint "
                f"moved? [Enter: {said}; or one of {', '.join(choices)}]"
            )
            if not answer:
                return None
            if answer in choices:
                return answer
            self._print(f"unknown joint {answer!r}; {did_you_mean(answer, choices)}")

    def checks_angle(self, joint: str) -> bool:
        """Check the joint against a protractor? (Enter = yes)."""
        return self._ask(f"Move the {joint} about 8° for you to measure? [Y/n]").lower() not in (
            "n",
            "no",
        )

    def measured_angle(self, joint: str, moved_deg: float) -> float | None:
        """Degrees measured (Enter: accept)."""
        while True:
            answer = self._ask(
                f"The {joint} moved {moved_deg:.1f}° by the speed reports. How many degrees did "
                "you measure? [Enter: accept]"
            )
            if not answer:
                return None
            try:
                value = float(answer)
            except ValueError:
                value = math.nan
            if math.isfinite(value) and value != 0.0:
                return value
            self._print(f"not an angle: {answer!r}")

    def wants_limits(self, joint: str) -> bool:
        """Search the joint's hard stops? (Enter = no)."""
        return self._ask(f"Find the {joint}'s hard stops by slow moves? [y/N]").lower() in (
            "y",
            "yes",
        )

    def drive_plan(self, kind: str) -> DrivePlan | None:
        """Distance per run; the default speeds."""
        unit = "m" if kind == LINEAR else "rad"
        answer = self._ask(
            f"Measure the {kind} drive constant (seed 000 §3.1)? Distance per run in {unit} "
            f"[Enter: skip; e.g. {DEFAULT_DRIVE_DISTANCE[kind]:.2f}]"
        )
        if not answer:
            return None
        try:
            distance = float(answer)
        except ValueError:
            self._print(f"not a distance: {answer!r}; skipped")
            return None
        return DrivePlan(kind, distance, DEFAULT_DRIVE_SPEEDS[kind])

    def zero_pose_ready(self, text: str) -> bool:
        """Enter when the arm is in its zero pose; "stop" (or "n") ends the calibration."""
        answer = self._ask(f"{text} Press Enter when it is [or type stop]").lower()
        return answer not in ("stop", "n", "no")

    def moved_positive(self, joint: str, positive: str) -> bool:
        """Did the joint move the positive way? y/n; "stop" stops."""
        while True:
            answer = self._ask(f"Did the {joint} {positive}? [y/n/stop]").lower()
            if answer in ("y", "yes"):
                return True
            if answer in ("n", "no"):
                return False
            if answer == "stop":
                raise CalibrationAbortedError(f"operator: stop (asked whether the {joint} moved)")
            self._print(f"answer y, n or stop, not {answer!r}")

    def drive_time(self, kind: str, index: int, commanded_s: float) -> float | None:
        """The stopwatch time of the run (Enter: drop it)."""
        answer = self._ask(
            f"Run {index + 1}: the OCU drove for {commanded_s:.2f} s. Your measured time in s? "
            "[Enter: drop the run]"
        )
        try:
            return float(answer) if answer else None
        except ValueError:
            return None
