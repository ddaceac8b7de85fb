"""`ocu calibrate --profile xarm1s` against the xArm simulator on a pseudo-terminal, mounted
"wrong" (a hidden offset per servo, a reversed elbow): the calibration finds the truth and
writes it; a goal with the written profile arrives at the true angle; a stop mid-move leaves
every servo with its stop move; a silent servo and an unreadable --out are refused.

Before this, `ocu calibrate --profile xarm1s` failed to load the xArm profile as an Engineer's
(exit 2), and the simulator had no mounting to calibrate against.
"""

from __future__ import annotations

import io
import math
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path

import pytest

from ocu.calibrate.cli import calibrate_main
from ocu.calibrate.guard import HeldFlag, StopSignal
from ocu.calibrate.operator import AnswersOperator
from ocu.calibrate.xarm import PROBE_S, XarmCalibrator, calibrated_xarm_text, raw_arm
from ocu.link.xarm import XarmLink
from ocu.profile.xarm import XarmProfile, load_xarm_profile
from ocu.records import Command, LinkState
from ocu.sim.xarm import Mounting, XarmSimulator, parse_mounting
from ocu.sim.xarm import main as sim_main

DEADLINE_S = 20.0
#: The hidden truth: servo -> mounting (the elbow, servo 4, reversed).
TRUTH = {6: Mounting(25), 5: Mounting(-40), 4: Mounting(60, reversed=True), 3: Mounting(-10)}
ALL_POSITIVE = {"base": True, "shoulder": True, "wrist_pitch": True, "wrist_roll": True}
#: What an operator watching the truth answers: the elbow went the negative way.
ANSWERS = {"zero_pose": True, "directions": {**ALL_POSITIVE, "elbow": False, "gripper": True}}


@pytest.fixture
def arm() -> XarmProfile:
    return load_xarm_profile("xarm1s")


def simulator(arm: XarmProfile, **options: object) -> Iterator[XarmSimulator]:
    sim = XarmSimulator(arm, **options)  # type: ignore[arg-type]
    sim.start()
    try:
        yield sim
    finally:
        sim.stop()


@pytest.fixture
def mounted(arm: XarmProfile) -> Iterator[XarmSimulator]:
    yield from simulator(arm, mounting=TRUTH)


def answers_file(tmp_path: Path, xarm: Mapping[str, object]) -> Path:
    directions = ", ".join(
        f"{joint} = {str(v).lower() if isinstance(v, bool) else repr(v).replace(chr(39), chr(34))}"
        for joint, v in xarm["directions"].items()  # type: ignore[attr-defined]
    )
    path = tmp_path / "answers.toml"
    path.write_text(
        f"[xarm]\nzero_pose = {str(xarm['zero_pose']).lower()}\ndirections = {{ {directions} }}\n",
        encoding="utf-8",
    )
    return path


def calibrate(sim: XarmSimulator, out: Path, answers: Path) -> tuple[int, str]:
    stdout = io.StringIO()
    status = calibrate_main(
        [
            "--profile",
            "xarm1s",
            "--robot",
            sim.path,
            "--out",
            str(out),
            "--answers",
            str(answers),
            "--on-stand",
        ],
        stdout=stdout,
    )
    return status, stdout.getvalue()


def wait_for(condition: Callable[[], bool], what: str, timeout_s: float = DEADLINE_S) -> None:
    """Poll a condition of the simulator's state until it holds (a deadline, no fixed wait)."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, f"{what} never happened"
        time.sleep(0.01)


def wait_for_the_last_stop_move(sim: XarmSimulator) -> None:
    """Wait until the board has run a stop move of every servo, the link's last frame (the
    simulator's thread may run behind the link's writes on a loaded machine)."""

    def ran() -> bool:
        last = sim.snapshot().last_move
        return (
            last is not None
            and last.duration_ms == 0
            and {servo for servo, _ in last.positions} == set(sim.board.servos)
        )

    wait_for(ran, "a stop move of every servo")


def test_offsets_and_a_reversed_joint_found_and_written(
    mounted: XarmSimulator, arm: XarmProfile, tmp_path: Path
) -> None:
    out = tmp_path / "my_xarm.toml"
    status, text = calibrate(mounted, out, answers_file(tmp_path, ANSWERS))
    assert status == 0, text
    written = load_xarm_profile(out)
    for joint in written.joints:
        truth = TRUTH.get(joint.servo, Mounting())
        assert abs(joint.offset_units - truth.offset_units) <= 1, (joint, text)
        assert joint.sign == (-1 if truth.reversed else 1), (joint, text)
    # Every other line kept, comments too.
    base = Path(arm.source).read_text(encoding="utf-8").splitlines()
    kept = [line for line in base if not line.startswith(("sign =", "offset ="))]
    assert all(line in out.read_text(encoding="utf-8").splitlines() for line in kept)
    assert "battery: 7400 mV" in text
    # Two timed moves per joint (out and back), then the link's shutdown: its stop move.
    wait_for_the_last_stop_move(mounted)
    moves = [move for _, move in mounted.board.moves_since(0.0)]
    assert len([move for move in moves if move.duration_ms > 0]) == 12
    # Each joint moved and came back: every servo at its zero again.
    snapshot = mounted.snapshot()
    for servo, position in snapshot.positions.items():
        assert abs(position - 500 - TRUTH.get(servo, Mounting()).offset_units) < 3


def test_the_written_profile_makes_a_goal_arrive_at_the_true_angle(
    mounted: XarmSimulator, tmp_path: Path
) -> None:
    out = tmp_path / "my_xarm.toml"
    status, text = calibrate(mounted, out, answers_file(tmp_path, ANSWERS))
    assert status == 0, text
    calibrated = load_xarm_profile(out)
    goals = {"shoulder": 0.3, "elbow": 0.4, "base": -0.2}
    link = XarmLink(calibrated, mounted.path, gui_alive_timeout_s=None)
    link.start()
    try:
        wait_for(lambda: link.state is LinkState.CONNECTED, "the link")
        wait_for(lambda: len(link.setpoints()) == 6, "every servo read")
        end = time.monotonic() + 1.5
        link.heartbeat()
        link.set_command(
            Command(
                velocities={name: goal / 1.5 for name, goal in goals.items()},
                goals=goals,
                until=dict.fromkeys(goals, end),
            )
        )

        def settled() -> bool:
            truth = mounted.board.true_angles_rad()
            return all(
                abs(truth[calibrated.joint(n).servo] - g) < math.radians(0.5)
                for n, g in goals.items()
            ) and all(abs(v) < 1.0 for v in mounted.snapshot().velocities.values())

        wait_for(settled, "the goals reached at their true angles")
    finally:
        link.shutdown()
    truth = mounted.board.true_angles_rad()
    # The uncalibrated profile would have put the elbow at -0.4 - 60 units off.
    assert abs(truth[4] - 0.4) < math.radians(0.5)


def test_a_stop_mid_move_leaves_every_servo_with_its_stop_move(
    mounted: XarmSimulator, arm: XarmProfile
) -> None:
    stop = StopSignal()
    link = XarmLink(raw_arm(arm), mounted.path)
    operator = AnswersOperator({"xarm": ANSWERS})
    calibrator = XarmCalibrator(link, arm, operator, deadman=HeldFlag(True), stop=stop)
    shoulder = 5
    zero = 500 + TRUTH[shoulder].offset_units

    def ctrl_c_when_the_shoulder_moves() -> None:
        deadline = time.monotonic() + DEADLINE_S
        while time.monotonic() < deadline and not stop.stopped:
            if abs(mounted.snapshot().setpoints[shoulder] - zero) > 4:
                stop.stop("SIGINT")
                return
            time.sleep(0.005)

    watcher = threading.Thread(target=ctrl_c_when_the_shoulder_moves)
    watcher.start()
    try:
        result = calibrator.run()
    finally:
        link.shutdown()
        watcher.join(DEADLINE_S)
    assert result.aborted == "SIGINT"
    assert stop.at is not None
    wait_for_the_last_stop_move(mounted)
    # After the stop (the board's clock is the monotonic clock): stop moves only, of every
    # servo. (Before it, a loaded machine may have seen the link's own watchdogs stop a joint.)
    after = [move for _, move in mounted.board.moves_since(stop.at)]
    assert after, "no stop move"
    assert all(move.duration_ms == 0 for move in after)
    assert {servo for move in after for servo, _ in move.positions} == {j.servo for j in arm.joints}
    # ... and the shoulder was stopped short of its 5° move.
    snapshot = mounted.snapshot()
    assert snapshot.setpoints[shoulder] == snapshot.targets[shoulder]
    assert abs(snapshot.targets[shoulder] - zero) < arm.units_per_rad * math.radians(5.0) - 1
    assert PROBE_S > 0.5  # the move was slow enough to be stopped half way


def test_the_operator_answering_stop_stops_and_writes_nothing(
    mounted: XarmSimulator, tmp_path: Path
) -> None:
    out = tmp_path / "my_xarm.toml"
    answers = {"zero_pose": True, "directions": {"base": True, "shoulder": "stop"}}
    status, text = calibrate(mounted, out, answers_file(tmp_path, answers))
    assert status == 1
    assert "stopped: operator: stop" in text
    assert "nothing written" in text
    assert not out.exists()
    wait_for_the_last_stop_move(mounted)
    # Nothing but stop moves after the operator's answer (the shoulder is held where it is).
    snapshot = mounted.snapshot()
    assert snapshot.setpoints == snapshot.targets


def test_a_servo_that_does_not_answer_is_refused_by_name(arm: XarmProfile, tmp_path: Path) -> None:
    for sim in simulator(arm, absent=[4]):
        out = tmp_path / "my_xarm.toml"
        status, text = calibrate(sim, out, answers_file(tmp_path, ANSWERS))
        assert status == 1
        assert "servo 4 (elbow) did not answer" in text
        assert not out.exists()
        assert sim.snapshot().moves == 0 or all(
            move.duration_ms == 0 for _, move in sim.board.moves_since(0.0)
        )


def test_an_offset_out_of_range_is_refused_with_the_reason(
    arm: XarmProfile, tmp_path: Path
) -> None:
    for sim in simulator(arm, mounting={5: Mounting(230)}):
        out = tmp_path / "my_xarm.toml"
        status, text = calibrate(sim, out, answers_file(tmp_path, ANSWERS))
        assert status == 1
        assert "the shoulder reads 730 in the zero pose, +230 units" in text
        assert not out.exists()


def test_an_unreadable_out_file_is_not_overwritten(
    mounted: XarmSimulator, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "my_xarm.toml"
    garbage = b"\xff\xfe not a profile [[["
    out.write_bytes(garbage)
    status, _ = calibrate(mounted, out, answers_file(tmp_path, ANSWERS))
    assert status == 2
    assert "not overwritten" in capsys.readouterr().err
    assert out.read_bytes() == garbage
    assert mounted.snapshot().moves == 0  # refused before anything moved


def test_the_text_keeps_every_line_but_sign_and_offset(arm: XarmProfile) -> None:
    from ocu.calibrate.xarm import XarmCalibrationResult

    result = XarmCalibrationResult(zero={"elbow": 560}, offsets={"elbow": 60}, signs={"elbow": -1})
    base = Path(arm.source).read_text(encoding="utf-8")
    text = calibrated_xarm_text(base, result, robot="/dev/pts/9", base_name="xarm1s")
    changed = [line for line in text.splitlines() if line not in base.splitlines()]
    assert changed[2:] == [
        "sign = -1  # measured: a 5° move seen",
        "offset = 60  # measured: read 560 in the zero pose",
    ]


def test_ctrl_c_to_ocu_calibrate_mid_move_stops_every_servo(
    mounted: XarmSimulator, tmp_path: Path
) -> None:
    out = tmp_path / "my_xarm.toml"
    command = [sys.executable, "-m", "ocu", "calibrate", "--profile", "xarm1s"]
    options = ["--robot", mounted.path, "--out", str(out), "--on-stand"]
    answers = answers_file(tmp_path, ANSWERS)
    elbow, zero = 4, 500 + TRUTH[4].offset_units
    with subprocess.Popen(
        [*command, *options, "--answers", str(answers)],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    ) as process:
        try:
            wait_for(
                lambda: abs(mounted.snapshot().setpoints[elbow] - zero) > 4,
                "the elbow's move",
                timeout_s=60.0,
            )
            signalled_at = mounted.board.clock()
            process.send_signal(signal.SIGINT)
            stdout, stderr = process.communicate(timeout=DEADLINE_S)
        finally:
            if process.poll() is None:
                process.kill()
                process.wait(DEADLINE_S)
    assert process.returncode == 1, stdout + stderr
    assert "Traceback" not in stderr
    assert "stopped: SIGINT; nothing written" in stdout
    assert not out.exists()
    wait_for_the_last_stop_move(mounted)
    after = [move for _, move in mounted.board.moves_since(signalled_at)]
    assert all(move.duration_ms == 0 for move in after)
    assert {servo for move in after for servo, _ in move.positions} == set(TRUTH) | {1, 2}
    snapshot = mounted.snapshot()
    assert abs(snapshot.targets[elbow] - zero) < arm_units(5.0)


def arm_units(degrees: float) -> float:
    return load_xarm_profile("xarm1s").units_per_rad * math.radians(degrees)


def test_ocu_sim_mount_options() -> None:
    assert parse_mounting("4:-40:reversed") == (4, Mounting(-40, reversed=True))
    assert parse_mounting("5:12") == (5, Mounting(12))
    for bad in ("4", "4:x", "4:10:backwards"):
        with pytest.raises(ValueError, match="bad mounting"):
            parse_mounting(bad)
    with pytest.raises(SystemExit):
        sim_main(["--profile", "xarm1s", "--mount", "9:10"])  # no servo 9


def test_the_deadman_let_go_mid_move_stops_it_and_held_again_finishes(
    mounted: XarmSimulator, arm: XarmProfile
) -> None:
    deadman = HeldFlag(True)
    stop = StopSignal()
    link = XarmLink(raw_arm(arm), mounted.path)
    operator = AnswersOperator({"xarm": ANSWERS})
    calibrator = XarmCalibrator(link, arm, operator, deadman=deadman, stop=stop)
    base, zero = 6, 500 + TRUTH[6].offset_units
    seen: dict[str, float] = {}

    def let_go_and_hold_again() -> None:
        deadline = time.monotonic() + DEADLINE_S
        while time.monotonic() < deadline:
            if abs(mounted.snapshot().setpoints[base] - zero) > 4:
                seen["released_at"] = mounted.board.clock()
                deadman.set(False)
                break
            time.sleep(0.005)
        while time.monotonic() < deadline:
            stops = [
                m for _, m in mounted.board.moves_since(seen["released_at"]) if m.duration_ms == 0
            ]
            if stops:
                seen["held_at"] = mounted.board.clock()
                seen["stopped_at_units"] = mounted.snapshot().targets[base]
                deadman.set(True)
                return
            time.sleep(0.005)

    watcher = threading.Thread(target=let_go_and_hold_again)
    watcher.start()
    try:
        result = calibrator.run()
    finally:
        link.shutdown()
        watcher.join(DEADLINE_S)
    assert result.aborted is None
    assert "held_at" in seen, "no stop move after the deadman was let go"
    # Stopped short of the 5° move, then finished: the base's sign and offset found.
    assert abs(seen["stopped_at_units"] - zero) < arm_units(5.0) - 1
    assert result.offsets["base"] == TRUTH[6].offset_units
    assert result.signs == {j.name: (-1 if j.name == "elbow" else 1) for j in arm.joints}


def test_a_calibrated_profile_calibrated_again_keeps_one_header(arm: XarmProfile) -> None:
    from ocu.calibrate.xarm import XarmCalibrationResult

    result = XarmCalibrationResult(zero={"base": 510}, offsets={"base": 10}, signs={"base": 1})
    base = Path(arm.source).read_text(encoding="utf-8")
    once = calibrated_xarm_text(base, result, robot="/dev/pts/9", base_name="xarm1s")
    twice = calibrated_xarm_text(once, result, robot="/dev/pts/9", base_name="my.toml")
    assert twice.count("written by `ocu calibrate`") == 1
    assert len(twice.splitlines()) == len(once.splitlines())


def test_noisy_readings_give_offsets_within_two_units(arm: XarmProfile, tmp_path: Path) -> None:
    for sim in simulator(arm, mounting=TRUTH, noise_units=1.0, seed=5):
        out = tmp_path / "my_xarm.toml"
        status, text = calibrate(sim, out, answers_file(tmp_path, ANSWERS))
        assert status == 0, text
        for joint in load_xarm_profile(out).joints:
            truth = TRUTH.get(joint.servo, Mounting())
            assert abs(joint.offset_units - truth.offset_units) <= 2, (joint, text)
            assert joint.sign == (-1 if truth.reversed else 1)


def test_the_written_file_is_an_xarm_profile_for_ocu_and_ocu_sim(
    arm: XarmProfile, tmp_path: Path
) -> None:
    from ocu.calibrate.xarm import XarmCalibrationResult, write_xarm_profile
    from ocu.calibrate.xarm_cli import is_xarm_profile_arg
    from ocu.profile import default_profile_path
    from ocu.profile.xarm import load_xarm_arm
    from ocu.sim.xarm import is_xarm_profile

    out = tmp_path / "my_xarm.toml"
    result = XarmCalibrationResult(zero={"elbow": 560}, offsets={"elbow": 60}, signs={"elbow": -1})
    write_xarm_profile(out, arm, result, robot="/dev/pts/9")
    loaded = load_xarm_arm(str(out))  # what `ocu --profile` and `ocu-ros` call
    assert loaded is not None
    assert (loaded.joint("elbow").sign, loaded.joint("elbow").offset_units) == (-1, 60)
    assert is_xarm_profile(["--profile", str(out)])
    assert is_xarm_profile_arg(str(out))
    # The Engineer's profile by its path stays the Engineer's.
    engineer = str(default_profile_path())
    assert load_xarm_arm(engineer) is None
    assert not is_xarm_profile_arg(engineer)
    assert not is_xarm_profile(["--profile", engineer])
