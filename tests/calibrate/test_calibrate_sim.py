"""`ocu calibrate` against the simulator playing unknown robots (`ocu-sim --scramble`)."""

from __future__ import annotations

import itertools
import math
import re
import signal
import statistics
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from PySide6.QtCore import QSettings, Qt
from PySide6.QtTest import QTest
from pytestqt.qtbot import QtBot

from ocu.calibrate.guard import HeldFlag, StopSignal
from ocu.calibrate.operator import AnswersOperator, AutoOperator
from ocu.calibrate.session import CalibrationConfig
from ocu.link.base import Link
from ocu.link.live import UdpLink
from ocu.profile import RobotProfile, load_profile
from ocu.records import LinkState
from ocu.sim.faults import FaultConfig
from ocu.sim.simulator import ReceivedRcp, RobotSimulator, SimState
from ocu.windows.main_window import MainWindow
from tests.calibrate.scrambled import BASE, assert_recovered, calibrate_scrambled, scrambled_truth
from tests.test_hotkeys import TABLE_4
from tests.windows.console_fixtures import mid_range_joints

pytestmark = pytest.mark.slow

# The stopping tests need no noise estimate: a short listening step.
QUICK = CalibrationConfig(listen_s=0.5)
LISTENING = re.compile(r"listening on (?P<host>[\d.]+):(?P<port>\d+)")
DEADLINE_S = 5.0
# Longer than a scan pulse waits for an answer (about 1.3 s), shorter than LINK LOST (3 s).
DROPOUT_S = 2.0


def first_motion(sim: RobotSimulator, timeout_s: float = 60.0) -> SimState:
    """Wait until the robot moves a joint (the calibration is under way)."""
    moving: list[SimState] = []

    def moves(state: SimState) -> bool:
        if any(v != 0.0 for v in state.velocities.values()):
            moving.append(state)
            return True
        return False

    assert sim.wait_until(moves, timeout_s), "the calibration never moved the robot"
    return moving[-1]


def zeros_after(received: list[ReceivedRcp], since: float) -> tuple[int, int]:
    """How many RCPs with motion, and how many zero RCPs, the robot got after `since`."""
    later = [r for r in received if r.time_s > since]
    moving = sum(1 for r in later if any(r.packet.axes))
    return moving, len(later) - moving


# ---- the command line, then the console on the calibrated profile ------------------------


@pytest.fixture
def scrambled_sim_process(tmp_path: Path) -> Iterator[tuple[tuple[str, int], Path]]:
    truth = tmp_path / "truth.toml"
    command = [sys.executable, "-m", "ocu.sim", "--port", "0", "--video-fps", "0"]
    command += ["--telemetry-hz", "20", "--scramble", "7", "--scramble-out", str(truth)]
    with subprocess.Popen(command, stdout=subprocess.PIPE, text=True) as sim:
        assert sim.stdout is not None
        match = LISTENING.search(sim.stdout.readline())
        assert match, "ocu-sim did not start"
        yield (match["host"], int(match["port"])), truth
        sim.send_signal(signal.SIGTERM)
        sim.wait(10)


def test_calibrate_yes_finds_the_robot_and_the_console_then_drives_it(
    scrambled_sim_process: tuple[tuple[str, int], Path], tmp_path: Path, qtbot: QtBot
) -> None:
    (host, port), truth_path = scrambled_sim_process
    out = tmp_path / "calibrated.toml"
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "ocu",
            "calibrate",
            "--robot",
            f"{host}:{port}",
            "--out",
            str(out),
            "--yes",
        ],
        capture_output=True,
        text=True,
        timeout=240,
        check=False,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert f"wrote {out}" in done.stdout
    truth, found = load_profile(truth_path), load_profile(out)
    for name, channel in truth.channels.items():
        assert (found.channels[name].axis, found.channels[name].axis_sign) == (
            channel.axis,
            channel.axis_sign,
        )
    for name, motor in truth.motors.items():
        if motor.channel is not None:
            assert found.motors[name].ticks_per_rad == pytest.approx(motor.ticks_per_rad, rel=0.02)
            assert found.motors[name].zero_offset_ticks == motor.zero_offset_ticks
            assert found.channels[motor.channel].axis_per_unit == pytest.approx(
                truth.channels[motor.channel].axis_per_unit, rel=0.02
            )
            entry = found.measured[f"motors.{name}.ticks_per_rad"]
            assert entry.residual is not None
            assert entry.samples is not None
            assert "sweeps" in entry.how
    # What was not measured stays an assumption; what was, is not one any more.
    assert found.provenance("motors.shoulder.limits_deg") == "assumption"
    assert found.provenance("channels.shoulder.axis") == "measured"
    assert "channels.*.axis" not in found.assumptions

    # The console on the calibrated profile drives the scrambled robot as table 4 says (its
    # joints mid-range: the gripper starts closed, and G's move back after T would be over
    # before a poll of the simulator saw it).
    with RobotSimulator(
        truth, telemetry_hz=10.0, video_fps=0.0, initial_joints=mid_range_joints(truth)
    ) as sim:
        settings = QSettings(str(tmp_path / "ocu.ini"), QSettings.Format.IniFormat)

        def link_factory() -> Link:
            return UdpLink(found, sim.address)

        window = MainWindow(found, link_factory, "scrambled simulator", settings)
        qtbot.addWidget(window)
        window.show()
        window.activateWindow()
        qtbot.waitUntil(window.isActiveWindow, timeout=5000)
        qtbot.waitUntil(lambda: window.link_status.state == LinkState.CONNECTED, timeout=5000)
        try:
            for key, (name, direction) in TABLE_4.items():
                QTest.keyPress(window, Qt.Key(ord(key)))

                def moves_that_way(c: str = name, d: int = direction) -> bool:
                    return sim.state().velocities[c] * d > 0

                try:
                    qtbot.waitUntil(moves_that_way, timeout=5000)
                except qtbot.TimeoutError:
                    events = [
                        window.event_log.item(i).text() for i in range(window.event_log.count())
                    ]
                    raise AssertionError(
                        f"{key} never moved {name} {direction:+d}: commanded "
                        f"{sim.state().commanded_velocities}, held {window.model.held_keys}, "
                        f"events {events[-5:]}"
                    ) from None
                QTest.keyRelease(window, Qt.Key(ord(key)))
                qtbot.waitUntil(lambda: sim.state().all_stopped, timeout=5000)
        finally:
            window.shutdown()


# ---- under the field's conditions ---------------------------------------------------------


def test_calibration_over_a_slow_lossy_link_with_noisy_encoders(tmp_path: Path) -> None:
    """40±10 ms each way, 5 % loss, ±0.15° readings, and a 2 s dropout during the scan."""
    truth = scrambled_truth(3)
    flippers = truth.channels["flippers"].axis
    assert flippers > 0
    sims: list[RobotSimulator] = []
    dropped = threading.Event()

    def drop_the_flippers_pulse(text: str) -> None:
        # Said just before the flippers' axis is pulsed: the link drops out for longer than
        # the pulse waits for an answer, so the robot never hears it; the calibrator must
        # pulse that axis again rather than give the flippers up.
        if re.match(rf"axis {flippers - 1}\b", text) and not dropped.is_set():
            dropped.set()
            sims[0].cut_link()
            threading.Timer(DROPOUT_S, sims[0].restore_link).start()

    def operator(sim: RobotSimulator) -> AutoOperator:
        sims.append(sim)
        return AutoOperator(drop_the_flippers_pulse)

    outcome = calibrate_scrambled(
        3,
        tmp_path,
        faults=FaultConfig(latency_ms=40.0, jitter_ms=10.0, loss=0.05),
        noise_deg=0.15,
        operator=operator,
    )
    assert dropped.is_set()
    assert outcome.result.aborted is None, outcome.result.aborted
    assert outcome.result.complete, outcome.result.findings
    assert_recovered(outcome, tolerance=0.02)
    last = outcome.received[-1]
    assert not any(last.packet.axes)
    # The link repeats the command at 50 Hz while calibrating (not the profile's 5 Hz): a
    # lost RCP, or one overtaken by the tick sent just before it, costs 20 ms of a pulse.
    times = [r.time_s for r in outcome.received]
    assert statistics.median(b - a for a, b in itertools.pairwise(times)) < 0.03


# ---- the guided mode ------------------------------------------------------------------------


class SimOperator(AnswersOperator):
    """A person at a robot with a protractor: measured angles come from the simulator's truth;
    the joint answers and the drive times from the hidden truth file."""

    def __init__(self, sim: RobotSimulator, truth: RobotProfile, deadman: HeldFlag) -> None:
        joints = {str(m.device_id): name for name, m in truth.motors.items() if m.has_position}
        linear = truth.linear_axis_per_m_s / BASE.linear_axis_per_m_s
        turn = truth.rotation_axis_per_rad_s / BASE.rotation_axis_per_rad_s
        super().__init__(
            {
                "joints": joints,
                "angles": {"shoulder": 0.0},
                "limits": ["gripper"],
                # Short runs: the times the operator types, not the robot's travel, carry
                # the truth the fit must find.
                "drive": {
                    "linear": {
                        "distance": 0.25,
                        "speeds": [0.3, 0.4],
                        "times_s": [0.25 * linear / v for v in (0.3, 0.4)],
                    },
                    "rotation": {
                        "distance": 0.5,
                        "speeds": [0.4, 0.6],
                        "times_s": [0.5 * turn / w for w in (0.4, 0.6)],
                    },
                },
            }
        )
        self.sim = sim
        self.deadman = deadman
        self.released = False
        self.zeros_while_released = 0
        self.waist_sweeps = threading.Event()
        self._before: dict[str, float] = {}

    def say(self, text: str) -> None:
        if text.startswith("Known angle"):
            self._before = self.sim.state().joints_rad
        if "waist: sweeps" in text:
            self.waist_sweeps.set()

    def let_go_while_the_waist_sweeps(self) -> None:
        """Let go of the deadman while the waist sweeps: it stops; held again, it goes on."""
        assert self.waist_sweeps.wait(120.0)
        first_motion(self.sim, 10.0)
        let_go = time.monotonic()
        self.deadman.set(False)
        # Released, the robot stops and keeps hearing zeros (commands in flight when the
        # deadman was let go may still arrive within the calibrator's 20 ms step).
        since = let_go + 0.1

        def stopped_hearing_zeros(state: SimState) -> bool:
            return state.all_stopped and zeros_after(self.sim.received_commands(), since)[1] >= 3

        assert self.sim.wait_until(stopped_hearing_zeros, DEADLINE_S)
        moving, self.zeros_while_released = zeros_after(self.sim.received_commands(), since)
        assert moving == 0
        self.released = True
        self.deadman.set(True)

    def measured_angle(self, joint: str, moved_deg: float) -> float | None:
        moved = self.sim.state().joints_rad[joint] - self._before[joint]
        return math.degrees(abs(moved))


def test_guided_calibration_finds_swapped_device_ids_limits_and_drive_constants(
    tmp_path: Path,
) -> None:
    truth = scrambled_truth(5, ids=True)
    deadman = HeldFlag(held=True)
    operators: list[SimOperator] = []

    def operator(sim: RobotSimulator) -> SimOperator:
        operators.append(SimOperator(sim, truth, deadman))
        return operators[0]

    def during(sim: RobotSimulator, stop: StopSignal, finished: threading.Event) -> None:
        operators[0].let_go_while_the_waist_sweeps()

    outcome = calibrate_scrambled(
        5,
        tmp_path,
        ids=True,
        operator=operator,
        deadman=deadman,
        config=CalibrationConfig(limit_speed_rad_s=0.5),
        during=during,
    )
    result = outcome.result
    assert result.aborted is None, result.aborted
    assert operators[0].released
    assert operators[0].zeros_while_released > 0
    found = outcome.profile
    for name, motor in truth.motors.items():
        assert found.motors[name].device_id == motor.device_id, name
    assert_recovered(outcome, to_the_stops=["gripper"])
    # The shoulder's ticks were checked against a measured angle.
    assert "measured as" in found.measured["motors.shoulder.ticks_per_rad"].how
    # The gripper's hard stops at 0° and 60°, found by slow moves, one degree inside.
    assert found.motors["gripper"].limits_deg == pytest.approx((1.0, 59.0), abs=0.7)
    assert found.provenance("motors.gripper.limits_deg") == "measured"
    # Seed 000's procedure: the drive constants within 2 % with their residual.
    assert found.linear_axis_per_m_s == pytest.approx(truth.linear_axis_per_m_s, rel=0.02)
    assert found.rotation_axis_per_rad_s == pytest.approx(truth.rotation_axis_per_rad_s, rel=0.02)
    entry = found.measured["si.linear_axis_per_m_s"]
    assert entry.samples == 2
    assert entry.residual is not None


# ---- stopping ---------------------------------------------------------------------------


def test_an_emergency_stop_ends_the_calibration_with_zeros(tmp_path: Path) -> None:
    stopped_at: list[float] = []

    def during(sim: RobotSimulator, stop: StopSignal, finished: threading.Event) -> None:
        first_motion(sim)
        stopped_at.append(time.monotonic())
        stop.stop("Space")
        assert sim.wait_until(lambda s: s.all_stopped, DEADLINE_S)

    outcome = calibrate_scrambled(11, tmp_path, config=QUICK, during=during)
    assert outcome.result.aborted == "Space"
    # The calibrator sees the stop within one control step (20 ms) and the e-stop burst
    # follows at once: after 50 ms nothing but zeros reach the robot.
    moving, _ = zeros_after(outcome.received, stopped_at[0] + 0.05)
    assert moving == 0
    _, zeros = zeros_after(outcome.received, stopped_at[0])
    assert zeros >= 5  # the e-stop burst, then the link's closing zeros


def test_link_lost_ends_the_calibration_and_nothing_resumes(tmp_path: Path) -> None:
    cut: list[float] = []

    def during(sim: RobotSimulator, stop: StopSignal, finished: threading.Event) -> None:
        first_motion(sim)
        sim.cut_link()
        cut.append(time.monotonic())
        # The robot's own watchdog stops it within 1 s; the OCU declares LINK LOST after 3 s
        # and the calibration ends. Only then does the link come back.
        assert sim.wait_until(lambda s: s.watchdog_stopped, 3.0)
        assert finished.wait(10.0)
        sim.restore_link()

    outcome = calibrate_scrambled(12, tmp_path, config=QUICK, during=during)
    assert outcome.result.aborted is not None
    assert "LINK LOST" in outcome.result.aborted
    moving, _ = zeros_after(outcome.received, cut[0] + 0.01)
    assert moving == 0


def test_an_encoder_that_jumps_stops_the_calibration(tmp_path: Path) -> None:
    truth = scrambled_truth(13)
    measured: list[str] = []
    first = threading.Event()

    def heard(text: str) -> None:
        # "<joint>: <n> ticks/rad ...": the first joint whose ticks per radian is known.
        if "ticks/rad" in text and not first.is_set():
            measured.append(text.partition(":")[0])
            first.set()

    def during(sim: RobotSimulator, stop: StopSignal, finished: threading.Event) -> None:
        # While the next joint sweeps, the measured joint's encoder jumps half its range.
        assert first.wait(120.0)
        motor = truth.motors[measured[0]]
        sim.set_raw_position(motor.name, (motor.zero_offset_ticks + 2**31) % 2**32)

    outcome = calibrate_scrambled(
        13,
        tmp_path,
        operator=lambda sim: AutoOperator(heard),
        config=QUICK,
        during=during,
    )
    assert measured
    assert outcome.result.aborted is not None
    assert f"implausible: the {measured[0]}'s position jumped" in outcome.result.aborted
    assert not any(outcome.received[-1].packet.axes)


def test_sigterm_stops_the_command_line_calibration_with_zeros_last(
    profile: RobotProfile, tmp_path: Path
) -> None:
    truth = scrambled_truth(14)
    out = tmp_path / "never.toml"
    with RobotSimulator(truth, telemetry_hz=20.0, video_fps=0.0) as sim:
        host, port = sim.address
        with subprocess.Popen(
            [
                sys.executable,
                "-m",
                "ocu",
                "calibrate",
                "--robot",
                f"{host}:{port}",
                "--out",
                str(out),
                "--yes",
            ],
            stdout=subprocess.PIPE,
            text=True,
        ) as process:
            first_motion(sim)
            process.send_signal(signal.SIGTERM)
            assert process.wait(15) == 1
            assert process.stdout is not None
            text = process.stdout.read()
        assert sim.wait_until(lambda s: s.all_stopped, DEADLINE_S)
        received = sim.received_commands()
    assert "stopped: SIGTERM; nothing written" in text
    assert not out.exists()
    assert not any(received[-1].packet.axes)
    assert received[-1].address[1] != 0
