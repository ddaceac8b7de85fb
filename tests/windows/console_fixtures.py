"""Console fixtures (the real simulator, the real link, settings in tmp_path) and helpers."""

from __future__ import annotations

import math
import os
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from PySide6.QtCore import QSettings
from PySide6.QtWidgets import QApplication
from pytestqt.qtbot import QtBot

from ocu.core_process import CoreSpec
from ocu.link.base import Link
from ocu.link.live import UdpLink
from ocu.profile import RobotProfile
from ocu.record.recorder import Recorder
from ocu.records import LinkState
from ocu.sim.simulator import ReceivedRcp, RobotSimulator, SimState
from ocu.windows.main_window import MainWindow

DEADLINE_MS = 5000
DEADLINE_S = DEADLINE_MS / 1000
RUN_TIMEOUT_S = 60


@pytest.fixture
def sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    """The simulator at 10 Hz telemetry, no video (keeps the two cores free)."""
    simulator = RobotSimulator(profile, telemetry_hz=10.0, video_fps=0.0)
    simulator.start()
    yield simulator
    simulator.stop()


@pytest.fixture
def settings(tmp_path: Path) -> QSettings:
    """Console settings in a temporary file, never the user's."""
    return QSettings(str(tmp_path / "ocu.ini"), QSettings.Format.IniFormat)


ConsoleFactory = Callable[..., MainWindow]


@pytest.fixture
def make_console(
    qtbot: QtBot, profile: RobotProfile, settings: QSettings
) -> Iterator[ConsoleFactory]:
    """Build, show and activate consoles; each is shut down after the test."""
    windows: list[MainWindow] = []

    def make(
        sim: RobotSimulator,
        *,
        connected: bool = True,
        recorder: Recorder | None = None,
        core: bool = False,
        **link_kwargs: Any,
    ) -> MainWindow:
        def link_factory() -> Link:
            return UdpLink(profile, sim.address, **link_kwargs)

        # core: the control core in a child process (ocu.core_process), on UDP to `sim`.
        host, port = sim.address
        spec = CoreSpec(profile, "engineer", f"{host}:{port}", options=link_kwargs)
        window = MainWindow(
            profile,
            None if core else link_factory,
            "simulator",
            settings,
            connect=connected,
            recorder=recorder,
            core=spec if core else None,
        )
        qtbot.addWidget(window)
        windows.append(window)
        window.show()
        window.activateWindow()
        qtbot.waitUntil(window.isActiveWindow, timeout=DEADLINE_MS)
        if connected:
            qtbot.waitUntil(
                lambda: window.link_status.state == LinkState.CONNECTED, timeout=DEADLINE_MS
            )
        return window

    yield make
    for window in windows:
        window.shutdown()
    QApplication.processEvents()


@pytest.fixture
def console(make_console: ConsoleFactory, sim: RobotSimulator) -> MainWindow:
    """One console connected to the simulator, active, with telemetry flowing."""
    return make_console(sim)


def wait_sim(
    qtbot: QtBot,
    sim: RobotSimulator,
    predicate: Callable[[SimState], bool],
    what: str,
    timeout_ms: int = DEADLINE_MS,
) -> SimState:
    """Wait, with Qt's event loop running, until the simulator's state satisfies predicate."""
    seen: list[SimState] = []

    def check() -> bool:
        state = sim.state()
        if predicate(state):
            seen.append(state)
            return True
        return False

    try:
        qtbot.waitUntil(check, timeout=timeout_ms)
    except qtbot.TimeoutError:
        raise AssertionError(f"simulator never showed: {what}") from None
    return seen[-1]


def wait_zeros(
    qtbot: QtBot, sim: RobotSimulator, what: str, *, more: int = 3, timeout_ms: int = DEADLINE_MS
) -> SimState:
    """Wait until the simulator heard a zero RCP last and stands still, then for `more` RCPs
    after it: every one of them is zero.

    A standstill alone does not prove the zeros arrived: the servos' deadband stops a joint
    under a small command (a centred tracking run) before the zeros reach the robot.
    """

    def zero_last() -> bool:
        received = sim.received_commands()
        return bool(received) and is_zero(received[-1])

    state = wait_sim(qtbot, sim, lambda s: s.all_stopped and zero_last(), what, timeout_ms)
    start = len(sim.received_commands())
    if more:
        qtbot.waitUntil(lambda: len(sim.received_commands()) >= start + more, timeout=timeout_ms)
    moving = [r for r in sim.received_commands()[start - 1 :] if not is_zero(r)]
    assert not moving, f"motion after the zeros: {moving[0]}"
    return state


def mid_range_joints(profile: RobotProfile) -> dict[str, float]:
    """Every bounded joint mid-range: each hotkey has room both ways.

    At a limit (the gripper starts closed) a key's move back is over within one telemetry
    period, or one poll of the simulator, and may never be seen.
    """
    return {
        motor.name: (motor.limits_rad[0] + motor.limits_rad[1]) / 2.0
        for motor in profile.motors.values()
        if motor.has_position
        and motor.limits_rad is not None
        and all(math.isfinite(v) for v in motor.limits_rad)
    }


def drive_axis(profile: RobotProfile, rcp: ReceivedRcp, channel: str) -> int:
    """The raw axis value of one channel in a received RCP."""
    return rcp.packet.axes[profile.channels[channel].axis]


def is_zero(rcp: ReceivedRcp) -> bool:
    """Whether an RCP commands no motion at all."""
    return not any(rcp.packet.axes)


def run_ocu(tmp_path: Path, *args: str) -> subprocess.CompletedProcess[str]:
    """`python -m ocu ARGS` offscreen, with its config (and recordings) under tmp_path."""
    env = {
        **os.environ,
        "QT_QPA_PLATFORM": "offscreen",
        "OCU_CONFIG_DIR": str(tmp_path / "cfg"),
        "OCU_RECORDINGS_DIR": str(tmp_path / "recordings"),
    }
    return subprocess.run(
        [sys.executable, "-m", "ocu", *args],
        env=env,
        capture_output=True,
        text=True,
        timeout=RUN_TIMEOUT_S,
        check=False,
    )


def qt_complaints(stderr: str) -> list[str]:
    """Lines that are not our log lines: Qt warnings, tracebacks."""
    return [
        line
        for line in stderr.splitlines()
        if line.strip() and not line[:4].isdigit() and "OpenGL_accelerate" not in line
    ]
