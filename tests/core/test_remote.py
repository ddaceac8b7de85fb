"""The control core in a process of its own (ocu.core_process, ocu.core.remote), without Qt.

Each test starts the real child process (`python -m ocu.core_process`) on a socket pair; its
hardware is the Engineer plug-in on a real UDP socket to the simulator in this process, and
what is checked about the robot is what the simulator received.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import textwrap
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from ocu.control.position import PositionError
from ocu.core.remote import CoreGoneError, RemoteError
from ocu.core.remote_link import RemoteLink
from ocu.core_process import (
    CORE_NICE,
    REALTIME_PRIORITY,
    CoreProcess,
    CoreProcessError,
    CoreSpec,
)
from ocu.profile import RobotProfile
from ocu.records import (
    TELEMETRY,
    VIDEO,
    VIDEO_FRAGMENT,
    DatagramReceived,
    LinkState,
    TelemetryFrame,
    VideoFrame,
)
from ocu.sim.simulator import RobotSimulator
from tests.core.core_parts import ProbeError

DEADLINE_S = 10.0
PROBE = "probe=tests.core.core_parts:probe"
ROOT = Path(__file__).resolve().parents[2]


def until(predicate: Callable[[], bool], what: str, timeout_s: float = DEADLINE_S) -> None:
    """Wait for `predicate` with a deadline (polling: there is no event loop here)."""
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"never happened: {what}")
        time.sleep(0.01)


@pytest.fixture
def sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    simulator = RobotSimulator(profile, telemetry_hz=10.0, video_fps=0.0)
    simulator.start()
    yield simulator
    simulator.stop()


@pytest.fixture
def core(profile: RobotProfile, sim: RobotSimulator) -> Iterator[CoreProcess]:
    host, port = sim.address
    process = CoreProcess(CoreSpec(profile, "engineer", f"{host}:{port}", parts=(PROBE,)))
    yield process
    process.stop()


def connect(core: CoreProcess, profile: RobotProfile) -> RemoteLink:
    link = RemoteLink(core.connection, profile, "simulator")
    core.model.set_connected(True)
    link.start()
    until(lambda: link.state is LinkState.CONNECTED, "the core's link connected")
    return link


def test_reads_calls_and_parts_answer_from_another_process(
    core: CoreProcess, profile: RobotProfile
) -> None:
    assert core.pid != os.getpid()
    model = core.model
    assert model.profile.name == profile.name
    assert model.arm is model.arm  # a part is one handle
    assert model.set_max_velocity("drive_linear", 0.1) == pytest.approx(0.1)
    assert model.max_velocity("drive_linear") == pytest.approx(0.1)
    assert not model.estopped
    model.emergency_stop("test")
    assert model.estopped
    assert "test" in model.estop_reason


def test_what_the_core_raises_is_raised_here_with_its_message(core: CoreProcess) -> None:
    with pytest.raises(PositionError):
        core.model.set_target("no_such_joint", 1.0)
    with pytest.raises(AttributeError, match="no_such_thing"):
        _ = core.model.no_such_thing
    probe = core.part("probe")
    with pytest.raises(ProbeError, match="on purpose"):
        probe.fail()
    with pytest.raises(RemoteError, match="UnpicklableError: this and that"):
        probe.fail_oddly()
    with pytest.raises(RemoteError, match="cannot cross"):
        probe.lock_out()
    assert probe.say(0) == 0  # the pipe still works after each


def test_events_come_in_order_and_a_calls_events_before_it_returns(core: CoreProcess) -> None:
    probe = core.part("probe")
    heard: list[int] = []
    probe.events.said.connect(heard.append)
    assert probe.say(50) == 50
    assert heard == list(range(50))
    maxima: list[tuple[str, float]] = []
    core.model.events.max_changed.connect(lambda channel, value: maxima.append((channel, value)))
    for value in (0.1, 0.2, 0.15):
        core.model.set_max_velocity("drive_linear", value)
    assert [channel for channel, _ in maxima] == ["drive_linear"] * 3
    assert [value for _, value in maxima] == pytest.approx([0.1, 0.2, 0.15])


def test_a_callable_passed_to_the_core_is_called_here(core: CoreProcess) -> None:
    got: list[tuple[int, str]] = []
    probe = core.part("probe")
    probe.call_back(lambda number, text: got.append((number, text)), 7, "seven")
    assert got == [(7, "seven")]


def test_the_core_drives_the_robot_and_its_link_events_come_here(
    core: CoreProcess, profile: RobotProfile, sim: RobotSimulator
) -> None:
    link = connect(core, profile)
    frames: list[TelemetryFrame] = []
    link.subscribe(
        lambda event: frames.append(event) if isinstance(event, TelemetryFrame) else None
    )
    until(lambda: len(frames) >= 2, "telemetry forwarded")
    core.model.set_velocity("drive_linear", 0.2)
    until(lambda: sim.state().velocities["drive_linear"] > 0, "the robot driving")
    core.model.set_velocity("drive_linear", 0.0)
    until(lambda: sim.state().all_stopped, "the robot stopped")
    assert link.stats().received > 0
    link.shutdown()


def test_the_gui_end_closed_halts_the_robot_with_zeros_and_ends_the_core(
    core: CoreProcess, profile: RobotProfile, sim: RobotSimulator
) -> None:
    connect(core, profile)
    core.model.set_velocity("drive_linear", 0.2)
    until(lambda: sim.state().velocities["drive_linear"] > 0, "the robot driving")
    core.connection.close()  # as the GUI's process dying does
    assert core.process.wait(DEADLINE_S) == 0
    # The zeros were sent before the core ended; the simulator's thread takes them in its time.
    until(lambda: sim.state().all_stopped, "the robot at rest")
    last = sim.received_commands()[-1]
    assert not any(last.packet.axes), "the last command was not zeros"
    assert not sim.state().watchdog_stopped, "the robot's watchdog stopped it, not the core"


def test_a_killed_gui_process_leaves_no_core_and_a_robot_at_rest(
    profile: RobotProfile, sim: RobotSimulator, tmp_path: Path
) -> None:
    host, port = sim.address
    script = tmp_path / "gui.py"
    script.write_text(
        textwrap.dedent(
            f"""
            import sys, time
            from ocu.core_process import CoreProcess, CoreSpec
            from ocu.core.remote_link import RemoteLink
            from ocu.profile import load_profile
            profile = load_profile()
            core = CoreProcess(CoreSpec(profile, "engineer", "{host}:{port}"))
            link = RemoteLink(core.connection, profile, "simulator")
            core.model.set_connected(True)
            link.start()
            core.model.set_velocity("drive_linear", 0.2)
            print(core.pid, flush=True)
            time.sleep(60)
            """
        ),
        encoding="utf-8",
    )
    gui = subprocess.Popen(
        [sys.executable, str(script)],
        stdout=subprocess.PIPE,
        text=True,
        cwd=ROOT,
        env=dict(os.environ, PYTHONPATH=str(ROOT)),
    )
    try:
        assert gui.stdout is not None
        core_pid = int(gui.stdout.readline())
        until(lambda: sim.state().velocities["drive_linear"] > 0, "the robot driving")
        gui.kill()
        gui.wait(DEADLINE_S)
        until(lambda: sim.state().all_stopped, "the robot stopped")
        assert not sim.state().watchdog_stopped, "the robot's watchdog stopped it, not the core"

        def gone() -> bool:
            try:
                os.kill(core_pid, 0)
            except ProcessLookupError:
                return True
            # A zombie until init reaps it: gone as far as the robot is concerned.
            with open(f"/proc/{core_pid}/stat", encoding="ascii") as stat:
                return stat.read().split(") ")[1].startswith("Z")

        until(gone, "the core process ended")
    finally:
        gui.kill()
        gui.wait(DEADLINE_S)
        if gui.stdout is not None:
            gui.stdout.close()


def test_a_killed_core_says_so_here_and_the_robot_stops_by_itself(
    core: CoreProcess, profile: RobotProfile, sim: RobotSimulator
) -> None:
    ended: list[bool] = []
    core._on_closed = lambda: ended.append(True)
    connect(core, profile)
    core.model.set_velocity("drive_linear", 0.2)
    until(lambda: sim.state().velocities["drive_linear"] > 0, "the robot driving")
    os.kill(core.pid, signal.SIGKILL)
    until(lambda: bool(ended), "the GUI's side told the core ended")
    with pytest.raises(CoreGoneError):
        core.model.set_velocity("drive_linear", 0.0)
    # Nobody commands the robot: its own watchdog (1 s without a command) stops it.
    until(lambda: sim.state().all_stopped, "the robot stopped by its watchdog")
    assert sim.state().watchdog_stopped


def test_a_core_that_cannot_start_is_an_error_naming_why(
    profile: RobotProfile, capfd: pytest.CaptureFixture[str]
) -> None:
    spec = CoreSpec(profile, "engineer", "127.0.0.1:9", parts=("x=tests.core.no_such:part",))
    with pytest.raises(CoreProcessError, match="did not start"):
        CoreProcess(spec)
    assert "No module named 'tests.core.no_such'" in capfd.readouterr().err


def test_video_frames_come_whole_and_the_raw_fragments_stay_in_the_core(
    profile: RobotProfile,
) -> None:
    simulator = RobotSimulator(profile, telemetry_hz=10.0, video_fps=10.0, extended=True)
    simulator.start()
    host, port = simulator.address
    core = CoreProcess(CoreSpec(profile, "engineer", f"{host}:{port}"))
    try:
        link = connect(core, profile)
        kinds: list[str] = []
        frames: list[VideoFrame] = []

        def heard(event: object) -> None:
            if isinstance(event, DatagramReceived):
                kinds.append(event.kind)
            elif isinstance(event, VideoFrame):
                frames.append(event)

        link.subscribe(heard)
        until(lambda: len(frames) >= 8 and TELEMETRY in kinds, "frames and raw telemetry")
        assert VIDEO_FRAGMENT not in kinds
        assert VIDEO not in kinds
        assert all(frame.jpeg.startswith(b"\xff\xd8") for frame in frames)
        link.shutdown()
    finally:
        core.stop()
        simulator.stop()


def test_the_core_runs_above_the_guis_priority_where_allowed(core: CoreProcess) -> None:
    ours = os.getpriority(os.PRIO_PROCESS, 0)
    theirs = os.getpriority(os.PRIO_PROCESS, core.pid)
    policy = os.sched_getscheduler(core.pid)
    if os.geteuid() == 0:  # CI and this machine: root may raise priority
        assert theirs == min(ours, CORE_NICE)
        assert policy == os.SCHED_RR
        assert os.sched_getparam(core.pid).sched_priority == REALTIME_PRIORITY
        until(lambda: core.core.timing().realtime, "the control thread timed")
        assert "real-time priority" in core.core.timing().text
    else:  # where the user may not, the core stays where it was started
        assert theirs in (ours, min(ours, CORE_NICE))
        assert policy in (os.SCHED_OTHER, os.SCHED_RR)


def test_a_default_socket_timeout_in_the_gui_does_not_break_the_pipe(
    profile: RobotProfile,
) -> None:
    # rospy sets socket.setdefaulttimeout() in the process that imports it (the ROS dock, a
    # test session): a socket pair made then is non-blocking, the child inherited that, read
    # EAGAIN at once and ended; the GUI's reader would have timed out when the core was idle.
    previous = socket.getdefaulttimeout()
    socket.setdefaulttimeout(0.2)
    try:
        core = CoreProcess(CoreSpec(profile, "engineer", "127.0.0.1:9"))
    finally:
        socket.setdefaulttimeout(previous)
    try:
        idle_until = time.monotonic() + 0.5  # longer than the timeout: nothing is read
        until(lambda: time.monotonic() > idle_until, "an idle half second")
        assert core.alive
        assert core.core.ping("still there") == "still there"
    finally:
        core.stop()
