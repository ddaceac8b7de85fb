"""The xArm link against the simulator through a real pseudo-terminal (pyserial), reading
what the SIMULATOR received and did: jogging as a stream of short moves, the release and the
e-stop stopping the servo, a killed OCU stopping the arm by the servos' own nature, LINK LOST
and nothing resuming, an impossible reading not believed; under latency, garbage and noise.
"""

from __future__ import annotations

import dataclasses
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from ocu.link.xarm import XarmLink
from ocu.profile.xarm import XarmProfile, load_xarm_profile
from ocu.records import (
    Command,
    LinkState,
    LinkStateChanged,
    SafetyEvent,
    StatusFrame,
    TelemetryFrame,
)
from ocu.sim.xarm import XarmSimulator, XarmSnapshot

ROOT = Path(__file__).resolve().parents[2]
DEADLINE_S = 10.0
BASE = 6  # the base's servo


def wait_for(check: Callable[[], bool], what: str, timeout_s: float = DEADLINE_S) -> None:
    deadline = time.monotonic() + timeout_s
    pause = threading.Event()
    while not check():
        if time.monotonic() > deadline:
            raise AssertionError(f"not {what} within {timeout_s} s")
        pause.wait(0.005)


class Events(list[object]):
    def of(self, kind: type) -> list[object]:
        return [e for e in list(self) if isinstance(e, kind)]


@pytest.fixture
def arm() -> XarmProfile:
    return load_xarm_profile("xarm1s")


def start(
    arm: XarmProfile, gui_alive_timeout_s: float | None = None, **sim_options: object
) -> tuple[XarmSimulator, XarmLink, Events]:
    simulator = XarmSimulator(arm, seed=5, **sim_options)  # type: ignore[arg-type]
    simulator.start()
    events = Events()
    link = XarmLink(
        arm, simulator.path, listener=events.append, gui_alive_timeout_s=gui_alive_timeout_s
    )
    link.start()
    wait_for(lambda: bool(events.of(TelemetryFrame)), "reading the servos")
    assert link.state is LinkState.CONNECTED
    return simulator, link, events


@pytest.fixture
def rig(arm: XarmProfile) -> Iterator[tuple[XarmSimulator, XarmLink, Events]]:
    simulator, link, events = start(arm)
    yield simulator, link, events
    link.shutdown()
    simulator.stop()


def jog_moves_since(simulator: XarmSimulator, since: float, servo: int) -> int:
    return sum(
        1
        for _, move in simulator.board.moves_since(since)
        if move.duration_ms > 0 and servo in dict(move.positions)
    )


def test_positions_and_battery_reach_the_console(
    rig: tuple[XarmSimulator, XarmLink, Events],
) -> None:
    _, link, events = rig
    frame = events.of(TelemetryFrame)[-1]
    assert isinstance(frame, TelemetryFrame)
    assert set(frame.readings) == set(link.arm.joint_names)
    assert all(r.angle_rad == 0.0 and r.plausible for r in frame.readings.values())
    wait_for(lambda: bool(events.of(StatusFrame)), "a battery report")
    status = events.of(StatusFrame)[-1]
    assert isinstance(status, StatusFrame)
    assert status.voltage_v == 7.4


def test_jog_streams_short_moves_and_the_release_stops_at_once(
    rig: tuple[XarmSimulator, XarmLink, Events],
) -> None:
    simulator, link, _ = rig
    speed = 0.3  # rad/s: 71.6 units/s at 240° for 1000 units
    link.set_command(Command({"base": speed}))
    wait_for(lambda: simulator.snapshot().setpoints[BASE] > 520, "the base moving")
    snapshot = simulator.snapshot()
    move = snapshot.last_move
    assert move is not None
    assert move.duration_ms == 150  # the profile's jog_move_s
    assert [servo for servo, _ in move.positions] == [BASE]
    # The setpoint moves at the speed asked (the moves chain from where it is).
    start_at, start_sp = snapshot.time, snapshot.setpoints[BASE]
    wait_for(lambda: simulator.snapshot().time > start_at + 0.5, "time passing")
    later = simulator.snapshot()
    rate = (later.setpoints[BASE] - start_sp) / (later.time - start_at)
    assert rate == pytest.approx(speed * link.arm.units_per_rad, rel=0.15)
    assert all(later.targets[s] == 500 for s in (1, 2, 3, 4, 5))
    # Release: a stop move (0 ms) to where the setpoint is; no jog move after it.
    link.set_command(Command())
    wait_for(
        lambda: (m := simulator.snapshot().last_move) is not None and m.duration_ms == 0,
        "a stop move",
    )
    stopped = simulator.snapshot()
    assert stopped.last_move is not None
    assert abs(stopped.targets[BASE] - stopped.setpoints[BASE]) <= 1.0  # where it was
    wait_for(lambda: simulator.snapshot().setpoints[BASE] == stopped.targets[BASE], "stopped")
    assert stopped.last_move_at is not None
    reads = stopped.position_reads
    wait_for(lambda: simulator.snapshot().position_reads >= reads + 3, "three more reads")
    assert jog_moves_since(simulator, stopped.last_move_at, BASE) == 0
    assert simulator.snapshot().targets[BASE] == stopped.targets[BASE]


def test_a_slow_jog_moves_at_its_speed(rig: tuple[XarmSimulator, XarmLink, Events]) -> None:
    """0.01 rad/s is 0.36 units per 0.15 s jog move, under the half unit a move's target
    is rounded to: the link keeps its setpoint in fractions of a unit, so the base still
    moves at the speed asked (the whole units the board takes come in turn)."""
    simulator, link, _ = rig
    speed = 0.01
    link.set_command(Command({"base": speed}))
    wait_for(lambda: simulator.snapshot().moves >= 1, "moving")
    start = simulator.snapshot()
    wait_for(lambda: simulator.snapshot().time > start.time + 2.0, "2 s of jogging")
    later = simulator.snapshot()
    link.set_command(Command())
    moved = later.setpoints[BASE] - start.setpoints[BASE]
    assert moved == pytest.approx(speed * link.arm.units_per_rad * 2.0, abs=1.5)


def test_a_goal_goes_as_one_move_of_several_servos(
    rig: tuple[XarmSimulator, XarmLink, Events],
) -> None:
    """Command.goals (a position command with a duration): one CMD_SERVO_MOVE with every
    servo given a goal and one duration, the time left to its end; not sent again while the
    same command stands, nor streamed."""
    simulator, link, _ = rig
    arm = link.arm
    since = simulator.snapshot().time
    end = link.clock() + 0.8
    goals = {"shoulder": 0.3, "elbow": -0.4, "wrist_pitch": 0.1}
    command = Command(
        velocities=dict.fromkeys(goals, 0.4),
        until=dict.fromkeys(goals, end),
        goals=goals,
    )
    link.set_command(command)
    link.set_command(command)
    wait_for(lambda: link.clock() > end + 0.3, "the move's end")
    moves = [move for _, move in simulator.board.moves_since(since)]
    assert len(moves) == 1, moves
    assert 700 <= moves[0].duration_ms <= 800
    expected = {
        arm.joint(name).servo: round(arm.raw_units(arm.joint(name), angle))
        for name, angle in goals.items()
    }
    assert dict(moves[0].positions) == expected
    wait_for(lambda: simulator.snapshot().setpoints[4] == expected[4], "the elbow's setpoint")
    # A stop while such a move runs holds every servo where its setpoint is.
    since = simulator.snapshot().time
    end = link.clock() + 2.0
    link.set_command(Command(velocities={"base": 0.3}, until={"base": end}, goals={"base": 0.5}))
    wait_for(lambda: simulator.snapshot().setpoints[BASE] > 510, "the base on its way")
    link.set_command(Command())
    wait_for(lambda: len(simulator.board.moves_since(since)) >= 2, "the stop move")
    stop = simulator.board.moves_since(since)[1][1]
    assert stop.duration_ms == 0
    assert dict(stop.positions)[BASE] < 600  # the goal was 500 + 0.5 rad = 619


def test_the_end_of_a_timed_move_sends_no_stop_move(arm: XarmProfile) -> None:
    """A timed move's duration is rounded up to whole milliseconds, so its setpoint may still
    be on its way when the controller's next command (no goal: the move's time is over)
    comes. A stop there would hold the servos where the move ends anyway: none is sent (the
    CI run where the xArm node's pose goal went as two moves). One mid-move still is."""
    from ocu.link.xarm_moves import XarmMoves
    from ocu.protocol.xarm import decode_servo_move

    moves = XarmMoves(arm)
    for servo in (3, 4, 5, 6):
        moves.first_reading(servo, 500, 0.0)
    goals = {"shoulder": 0.3, "elbow": -0.4}
    end = 0.8004  # 801 ms on the wire
    command = Command(
        velocities=dict.fromkeys(goals, 0.4), until=dict.fromkeys(goals, end), goals=goals
    )
    frames, _ = moves.frames(command, 0.0)
    assert [decode_servo_move(f[4:]).duration_ms for f in frames] == [801]
    assert moves.moving(end + 0.0003)  # the setpoints' last 0.7 ms
    frames, _ = moves.frames(Command(), end + 0.0003)
    assert frames == []
    # Mid-move, the same is a stop at where the setpoints are.
    back = {"shoulder": 0.0, "elbow": 0.0}
    command = Command(
        velocities=dict.fromkeys(back, 0.4), until=dict.fromkeys(back, 2.0), goals=back
    )
    frames, _ = moves.frames(command, 1.0)
    assert len(frames) == 1
    assert moves.moving(1.2)
    frames, _ = moves.frames(Command(), 1.2)
    assert [decode_servo_move(f[4:]).duration_ms for f in frames] == [0]
    # A jog released within its target's unit still gets its stop move (a jog's setpoint
    # moves in fractions of a unit; the stop is what the release is).
    frames, _ = moves.frames(Command({"elbow": 0.01}), 2.0)
    assert [decode_servo_move(f[4:]).duration_ms for f in frames] == [150]
    ramp = moves.targets()[4]
    assert round(ramp.value(2.05)) == round(ramp.end)
    frames, _ = moves.frames(Command(), 2.05)
    assert [decode_servo_move(f[4:]).duration_ms for f in frames] == [0]


def test_a_late_goal_is_never_run_faster_than_the_joints_top_speed(
    rig: tuple[XarmSimulator, XarmLink, Events],
) -> None:
    """A goal whose end is 20 ms away (a command that came late) would be a jump of the
    servo: the move takes the time the joint's top speed needs, the others in it too."""
    simulator, link, _ = rig
    arm = link.arm
    since = simulator.snapshot().time
    end = link.clock() + 0.02
    goals = {"elbow": -0.5, "shoulder": 0.1}
    link.set_command(
        Command(velocities=dict.fromkeys(goals, 1.0), until=dict.fromkeys(goals, end), goals=goals)
    )
    wait_for(lambda: bool(simulator.board.moves_since(since)), "the move")
    move = simulator.board.moves_since(since)[0][1]
    assert {servo for servo, _ in move.positions} == {4, 5}  # still one synchronized move
    top_speed = arm.joint("elbow").max_speed_rad_s * arm.units_per_rad  # 60°/s in units/s
    travel = abs(dict(move.positions)[4] - 500)  # the elbow's, from the middle
    assert move.duration_ms >= travel / top_speed * 1000
    link.set_command(Command())


def test_reads_are_rate_limited_while_moves_stream(
    rig: tuple[XarmSimulator, XarmLink, Events],
) -> None:
    simulator, link, _ = rig
    link.set_command(Command({"elbow": 0.2}))
    wait_for(lambda: simulator.snapshot().moves >= 1, "moving")
    first = simulator.snapshot()
    wait_for(lambda: simulator.snapshot().time > first.time + 2.0, "2 s of jogging")
    last = simulator.snapshot()
    link.set_command(Command())
    moves = last.moves - first.moves
    reads = last.position_reads - first.position_reads
    # Up to 20 moves a second (jog_period_s 0.05; fewer when a loaded machine delays the
    # link's loop), at most one read every read_period_moving_s (0.15 s) whatever the load.
    assert reads <= 2.0 / link.arm.timing.read_period_moving_s + 2
    assert reads >= 2
    assert moves > 2 * reads


def test_emergency_stop_holds_every_servo_and_latches(
    rig: tuple[XarmSimulator, XarmLink, Events],
) -> None:
    simulator, link, events = rig
    link.set_command(Command({"base": 0.5, "shoulder": -0.3}))
    wait_for(lambda: simulator.snapshot().setpoints[5] < 490, "the shoulder moving")
    link.emergency_stop("test")
    wait_for(
        lambda: (
            (m := simulator.snapshot().last_move) is not None
            and m.duration_ms == 0
            and len(m.positions) == 6
        ),
        "the stop move for all six",
    )
    stopped = simulator.snapshot()
    wait_for(lambda: simulator.snapshot().setpoints == stopped.targets, "every servo stopped")
    assert stopped.last_move_at is not None
    reads = stopped.position_reads
    wait_for(lambda: simulator.snapshot().position_reads >= reads + 3, "three more reads")
    assert jog_moves_since(simulator, stopped.last_move_at, BASE) == 0
    assert any("EMERGENCY STOP" in e.message for e in events.of(SafetyEvent))  # type: ignore[attr-defined]


def test_a_killed_ocu_stops_the_arm_within_half_a_second(arm: XarmProfile) -> None:
    """The link in a child process jogs the base at 0.5 rad/s; SIGKILL. The servos' setpoint
    stops at the last move's target within its time (0.15 s), whatever the OCU does."""
    simulator = XarmSimulator(arm)
    simulator.start()
    with subprocess.Popen(
        [sys.executable, "-m", "tests.link.xarm_child", simulator.path, "base", "0.5"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        cwd=ROOT,
    ) as child:
        try:
            assert child.stdout is not None
            assert child.stdout.readline().strip() == "moving"
            wait_for(lambda: simulator.snapshot().moves >= 10, "ten jog moves")
            child.kill()
            killed_at = time.monotonic()
            child.wait(DEADLINE_S)
            at_kill = simulator.snapshot()
            wait_for(lambda: simulator.snapshot().time > killed_at + 0.5, "half a second after")
            after = simulator.snapshot()
        finally:
            if child.poll() is None:
                child.kill()
            simulator.stop()
    assert after.last_move is not None
    assert after.last_move_at is not None
    # The stream's last move lasts one jog move (0.15 s): the setpoint has stopped at its
    # target half a second after the kill (the simulator reads what the child wrote before
    # dying as it comes: its time stamps, not the child's, so a loaded machine's stall of the
    # simulator's thread is not counted against the link).
    assert after.last_move.duration_ms == round(arm.timing.jog_move_s * 1000)
    assert after.last_move_at + after.last_move.duration_ms / 1000.0 <= after.time
    assert after.setpoints[BASE] == after.targets[BASE]
    # Travel of the setpoint after the kill: at most one move's worth at 0.5 rad/s.
    one_move = 0.5 * arm.units_per_rad * arm.timing.jog_move_s
    assert after.targets[BASE] - at_kill.setpoints[BASE] <= one_move + 1.0


def test_an_impossible_reading_is_not_believed_nor_moved_from(arm: XarmProfile) -> None:
    simulator, link, events = start(arm, initial={BASE: 3000})
    try:
        frame = events.of(TelemetryFrame)[-1]
        assert isinstance(frame, TelemetryFrame)
        assert frame.readings["base"].fault == "servo 6 reported 3000, outside its range"
        assert frame.readings["base"].angle_rad is None
        link.set_command(Command({"base": 0.5, "elbow": 0.2}))
        wait_for(lambda: simulator.snapshot().targets[4] > 505, "the elbow moving")
        assert all(BASE not in dict(m.positions) for _, m in simulator.board.moves_since(0.0))
    finally:
        link.shutdown()
        simulator.stop()


def test_link_lost_stops_and_nothing_resumes(arm: XarmProfile) -> None:
    simulator, link, events = start(arm)
    try:
        jog = Command({"base": 0.3})
        link.set_command(jog)
        wait_for(lambda: simulator.snapshot().targets[BASE] > 510, "the base moving")
        simulator.set_mute(True)  # replies stop; moves still reach the board
        wait_for(lambda: link.state is LinkState.LOST, "LINK LOST", timeout_s=5.0)
        lost = [e for e in events.of(LinkStateChanged) if e.state is LinkState.LOST]  # type: ignore[attr-defined]
        assert "no reply from the board" in lost[-1].reason  # type: ignore[attr-defined]
        # The stop move LINK LOST sends: everything sent before it has run (a loaded machine
        # may have held the simulator's thread while jog moves waited in the terminal).
        wait_for(
            lambda: (m := simulator.snapshot().last_move) is not None and m.duration_ms == 0,
            "the stop move",
        )
        stopped_at = simulator.snapshot().last_move_at
        assert stopped_at is not None
        wait_for(
            lambda: simulator.snapshot().setpoints[BASE] == simulator.snapshot().targets[BASE],
            "the base's setpoint stopped",
        )
        simulator.set_mute(False)
        wait_for(lambda: link.state is LinkState.CONNECTED, "connected again")
        link.set_command(jog)  # the held command, again: not resumed
        reads = simulator.snapshot().position_reads
        wait_for(lambda: simulator.snapshot().position_reads >= reads + 3, "three more reads")
        assert jog_moves_since(simulator, stopped_at, BASE) == 0
        link.set_command(Command({"base": 0.2}))  # a new command moves again
        wait_for(lambda: jog_moves_since(simulator, stopped_at, BASE) > 0, "moving again")
    finally:
        link.shutdown()
        simulator.stop()


def test_silent_control_thread_stops_the_jog(arm: XarmProfile) -> None:
    simulator, link, events = start(arm, gui_alive_timeout_s=0.3)
    try:
        link.heartbeat()
        link.set_command(Command({"base": 0.3}))
        wait_for(lambda: simulator.snapshot().targets[BASE] > 510, "the base moving")
        # No heartbeat from here on.
        wait_for(
            lambda: any("control thread silent" in e.message for e in events.of(SafetyEvent)),  # type: ignore[attr-defined]
            "the GUI-alive watchdog",
        )
        wait_for(
            lambda: (m := simulator.snapshot().last_move) is not None and m.duration_ms == 0,
            "the stop move",
        )
    finally:
        link.shutdown()
        simulator.stop()


def test_jog_under_latency_garbage_and_noise(arm: XarmProfile) -> None:
    """The field: 30 ms each way, garbage before a third of the replies, 2 units of noise.
    The jog still runs, every reading is believed or refused by rule, the release stops it."""
    simulator, link, events = start(arm, latency_ms=30.0, garbage_rate=0.3, noise_units=2.0)
    try:
        link.set_command(Command({"wrist_pitch": 0.4}))
        wait_for(lambda: simulator.snapshot().setpoints[3] > 560, "the wrist moving")
        readings_before = len(events.of(TelemetryFrame))
        wait_for(lambda: len(events.of(TelemetryFrame)) >= readings_before + 4, "readings go on")
        link.set_command(Command())
        wait_for(
            lambda: simulator.snapshot().setpoints[3] == simulator.snapshot().targets[3],
            "the wrist's setpoint stopped",
        )
        released = simulator.snapshot()
        reads = released.position_reads
        wait_for(lambda: simulator.snapshot().position_reads >= reads + 3, "three more reads")
        assert simulator.snapshot().targets[3] == released.targets[3]
        assert link.bad_frames > 0
        frames = [f for f in events.of(TelemetryFrame) if isinstance(f, TelemetryFrame)]
        assert all(r.plausible for f in frames for r in f.readings.values())
        last = frames[-1].readings["wrist_pitch"].angle_rad
        assert last is not None
        expected = link.arm.angle_rad(link.arm.joint("wrist_pitch"), released.targets[3])
        assert last == pytest.approx(expected, abs=0.2)
    finally:
        link.shutdown()
        simulator.stop()


def test_each_reading_carries_its_round_trip(arm: XarmProfile) -> None:
    """The request-to-reply time of each position read is the reading's delay (what the
    Engineer's link measures from its sequence numbers): 40 ms each way shows as 80 ms and
    more, none at all as a few ms (the frames at 115200 baud)."""
    for latency_ms, low, high in ((0.0, 0.0, 0.040), (40.0, 0.080, 0.300)):
        simulator, link, events = start(arm, latency_ms=latency_ms)
        try:
            count = len(events.of(TelemetryFrame))

            def five_more(seen: Events = events, n: int = count) -> bool:
                return len(seen.of(TelemetryFrame)) >= n + 5

            wait_for(five_more, "five readings")
            frames = [f for f in events.of(TelemetryFrame) if isinstance(f, TelemetryFrame)]
            delays = [f.delay_s for f in frames[-5:]]
            assert all(d is not None and low <= d <= high for d in delays), (latency_ms, delays)
        finally:
            link.shutdown()
            simulator.stop()


def test_shutdown_sends_the_stop_move_last(arm: XarmProfile) -> None:
    simulator, link, _ = start(arm)
    link.set_command(Command({"gripper": 0.4}))
    wait_for(lambda: simulator.snapshot().setpoints[1] > 520, "the gripper moving")
    link.shutdown()
    try:
        wait_for(
            lambda: (m := simulator.snapshot().last_move) is not None and m.duration_ms == 0,
            "the stop move",
        )
        snapshot: XarmSnapshot = simulator.snapshot()
        wait_for(lambda: simulator.snapshot().setpoints[1] == snapshot.targets[1], "stopped")
        assert link.state is LinkState.CLOSED
    finally:
        simulator.stop()


def test_a_joint_beyond_its_limit_is_not_pushed_further_nor_pulled_back(
    arm: XarmProfile,
) -> None:
    """The base's limit at 700 units, the servo found at 800 (set by hand, say): a jog
    outward leaves it where it is (no move back to the limit either), a jog inward moves it."""
    base = dataclasses.replace(arm.joint("base"), max_units=700)
    limited = dataclasses.replace(
        arm, joints=tuple(base if j.name == "base" else j for j in arm.joints)
    )
    simulator, link, _ = start(limited, initial={BASE: 800})
    try:
        link.set_command(Command({"base": 0.3}))  # outward
        wait_for(lambda: simulator.snapshot().moves >= 5, "jog moves")
        assert simulator.snapshot().targets[BASE] == 800
        link.set_command(Command({"base": -0.3}))  # inward
        wait_for(lambda: simulator.snapshot().targets[BASE] < 790, "the base coming back in")
    finally:
        link.shutdown()
        simulator.stop()


def test_a_port_that_cannot_be_opened_is_link_lost_and_retried(
    arm: XarmProfile, tmp_path: Path
) -> None:
    events = Events()
    link = XarmLink(arm, str(tmp_path / "ttyUSB9"), listener=events.append)
    link.start()
    try:
        wait_for(lambda: link.state is LinkState.LOST, "LINK LOST")
        changes = [e for e in events.of(LinkStateChanged) if isinstance(e, LinkStateChanged)]
        assert "cannot open" in changes[-1].reason
        assert str(tmp_path / "ttyUSB9") in changes[-1].reason
        link.set_command(Command({"base": 0.3}))
        assert not link.command.is_motion  # held, not sent: nothing to send it to
    finally:
        link.shutdown()
    assert link.state is LinkState.CLOSED
