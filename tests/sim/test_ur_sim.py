"""The UR simulator over real TCP sockets on 127.0.0.1: what a client reads and what the arm
does with the URScript it sends. Every wait is on a condition with a deadline; timing claims
are checked against the controller time in the packets, so a loaded machine cannot fail them.
"""

from __future__ import annotations

import itertools
import re
import socket
import subprocess
import sys
import time
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from ocu.profile.keys import ProfileError
from ocu.profile.ur import load_ur_profile, shipped_ur_profiles
from ocu.protocol.ur import (
    PackageType,
    RealtimeState,
    RobotMode,
    RobotState,
    SafetyMode,
    StreamSplitter,
    VersionMessage,
    decode_primary,
    movej,
    realtime_size,
    servoj,
    speedj,
    stopj,
)
from ocu.sim.ur import UrSimulator
from ocu.sim.ur_arm import tcp_pose

DEADLINE_S = 10.0
_OPEN: list[socket.socket] = []


@pytest.fixture(autouse=True)
def _close_clients() -> Iterator[None]:
    yield
    while _OPEN:
        _OPEN.pop().close()


@dataclass
class Received:
    """A realtime packet and when it arrived (monotonic s)."""

    state: RealtimeState
    arrived_s: float


class RealtimeClient:
    """A client of the realtime port: reads whole packets, sends URScript."""

    def __init__(self, port: int, size: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=DEADLINE_S)
        _OPEN.append(self.sock)
        self.splitter = StreamSplitter.realtime({size})
        self.size = size
        self.pending: list[Received] = []

    def close(self) -> None:
        self.sock.close()

    def send(self, data: bytes) -> None:
        self.sock.sendall(data)

    def next(self) -> Received:
        """The next packet, waiting at most DEADLINE_S."""
        deadline = time.monotonic() + DEADLINE_S
        while not self.pending:
            self.sock.settimeout(max(0.01, deadline - time.monotonic()))
            data = self.sock.recv(65536)
            if not data:
                raise ConnectionError("the simulator closed the realtime connection")
            now = time.monotonic()
            for packet in self.splitter.feed(data):
                self.pending.append(Received(RealtimeState.decode(packet), now))
        return self.pending.pop(0)

    def until(self, condition: Callable[[RealtimeState], bool], what: str) -> list[Received]:
        """Every packet up to and including the first that meets `condition`."""
        deadline = time.monotonic() + DEADLINE_S
        seen: list[Received] = []
        while time.monotonic() < deadline:
            seen.append(self.next())
            if condition(seen[-1].state):
                return seen
        raise AssertionError(f"no realtime packet {what} within {DEADLINE_S} s")


class PrimaryClient:
    """A client of the primary or secondary port: whole packets, decoded."""

    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=DEADLINE_S)
        _OPEN.append(self.sock)
        self.splitter = StreamSplitter.primary()
        self.pending: list[bytes] = []

    def close(self) -> None:
        self.sock.close()

    def next_raw(self) -> bytes:
        deadline = time.monotonic() + DEADLINE_S
        while not self.pending:
            self.sock.settimeout(max(0.01, deadline - time.monotonic()))
            data = self.sock.recv(65536)
            if not data:
                raise ConnectionError("the simulator closed the connection")
            self.pending += self.splitter.feed(data)
        return self.pending.pop(0)

    def next_state(self) -> RobotState:
        deadline = time.monotonic() + DEADLINE_S
        while time.monotonic() < deadline:
            packet = decode_primary(self.next_raw())
            if isinstance(packet, RobotState):
                return packet
        raise AssertionError("no robot state")


@pytest.fixture
def make_sim() -> Iterator[Callable[..., UrSimulator]]:
    sims: list[UrSimulator] = []

    def make(profile: str = "ur5e", **options: object) -> UrSimulator:
        sim = UrSimulator(load_ur_profile(profile), ports=(0, 0, 0), **options)  # type: ignore[arg-type]
        sim.start()
        sims.append(sim)
        return sim

    yield make
    for sim in sims:
        sim.stop()


def realtime_client(sim: UrSimulator) -> RealtimeClient:
    return RealtimeClient(sim.ports["realtime"], sim.realtime_size)


def read_until_closed(client: RealtimeClient) -> None:
    """Read packets until the connection closes (ConnectionError) or DEADLINE_S passes."""
    deadline = time.monotonic() + DEADLINE_S
    while time.monotonic() < deadline:
        client.next()


def wait_for(condition: Callable[[], bool], what: str) -> None:
    deadline = time.monotonic() + DEADLINE_S
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"not {what} within {DEADLINE_S} s")
        time.sleep(0.002)  # polling interval, not synchronisation: the condition decides


VERSIONS = [
    # profile, controller version, realtime size, rate (Hz)
    ("ur5", (3, 2, 0), 1060, 125.0),
    ("ur5", (3, 15, 8), 1140, 125.0),
    ("ur5e", (5, 10, 0), 1220, 500.0),
]


@pytest.mark.parametrize(("profile", "version", "size", "rate"), VERSIONS)
def test_version_first_then_robot_state(
    make_sim: Callable[..., UrSimulator],
    profile: str,
    version: tuple[int, int, int],
    size: int,
    rate: float,
) -> None:
    sim = make_sim(profile, controller_version=version)
    for kind in ("primary", "secondary"):
        client = PrimaryClient(sim.ports[kind])
        first = decode_primary(client.next_raw())
        assert isinstance(first, VersionMessage)
        assert (first.major, first.minor, first.bugfix) == version
        state = client.next_state()
        mode = state.robot_mode
        assert mode is not None
        assert mode.robot_mode == RobotMode.RUNNING
        assert not mode.protective_stopped
        assert len(mode.encode()) == (47 if version >= (3, 5, 0) else 46)
        joints = state.joint_data
        assert joints is not None
        assert joints.joints[1].q_actual == pytest.approx(-1.57)
        board = state.masterboard
        assert board is not None
        assert board.safety is SafetyMode.NORMAL
        client.close()
    assert realtime_size(version[:2]) == size


@pytest.mark.parametrize(("profile", "version", "size", "rate"), VERSIONS)
def test_realtime_size_and_rate(
    make_sim: Callable[..., UrSimulator],
    profile: str,
    version: tuple[int, int, int],
    size: int,
    rate: float,
) -> None:
    sim = make_sim(profile, controller_version=version)
    client = realtime_client(sim)
    first = client.next()
    received = [first]
    while received[-1].arrived_s - first.arrived_s < 1.0:
        received.append(client.next())
    client.close()
    assert all(r.state.size == size for r in received)
    times = [r.state.time_s for r in received]
    steps = {round(b - a, 9) for a, b in itertools.pairwise(times)}
    assert steps == {round(1.0 / rate, 9)}  # one packet per control period, none skipped
    controller_span = times[-1] - times[0]
    wall_span = received[-1].arrived_s - first.arrived_s
    # The controller clock runs with the wall clock: the packets come at `rate`.
    assert controller_span / wall_span == pytest.approx(1.0, abs=0.25)
    assert len(received) >= 0.75 * rate


def test_speedj_moves_then_the_robot_side_watchdog_stops_it(
    make_sim: Callable[..., UrSimulator],
) -> None:
    """speedj streamed at 125 Hz with t = 0.1 s; the stream stops; the arm must start braking
    t after the last command and be at rest v/a later: the controller's own watchdog."""
    sim = make_sim("ur5e")
    client = realtime_client(sim)
    speed, accel, t = 0.5, 15.0, 0.1
    command = speedj([0.0, 0.0, 0.0, 0.0, 0.0, speed], accel, t)
    last_sent: Received | None = None
    start = client.next()
    while True:
        packet = client.next()
        if round(packet.state.time_s / 0.008, 6) % 1 == 0:  # every 4th packet: 125 Hz
            if packet.state.time_s - start.state.time_s > 0.4:
                break
            client.send(command)
            last_sent = packet
    assert last_sent is not None
    moving = client.until(lambda s: s.qd_actual[5] >= speed - 1e-9, "at full speed")
    rest = client.until(lambda s: s.qd_actual[5] == 0.0, "at rest")
    braking = next(r for r in rest if r.state.qd_actual[5] < speed - 1e-9)
    at_rest = rest[-1]
    assert moving[-1].state.q_actual[5] > 0.05
    # Controller time from the cycle the last speedj took effect: the arm keeps its speed for
    # t, then brakes at a (the realtime packet shows a cycle's speed one cycle later).
    last_command_s = sim.snapshot().last_command_s
    brake_after = braking.state.time_s - last_command_s
    rest_after = at_rest.state.time_s - last_command_s
    period = sim.period_s
    assert t <= brake_after <= t + 2 * period + 1e-9
    assert rest_after <= t + speed / accel + 3 * period + 1e-9
    wall_rest_after = at_rest.arrived_s - last_sent.arrived_s
    print(
        f"speedj watchdog: braking {brake_after * 1000:.0f} ms, at rest {rest_after * 1000:.0f} ms "
        f"after the last command took effect (controller time); {wall_rest_after * 1000:.0f} ms "
        "from the client's last send to reading the arm at rest (wall time)"
    )
    assert sim.snapshot().program is None
    client.close()


def test_stopj_decelerates_at_its_acceleration(make_sim: Callable[..., UrSimulator]) -> None:
    sim = make_sim("ur5e")
    client = realtime_client(sim)
    client.send(speedj([0.0, 0.3, 0.0, 0.0, 0.0, 0.0], 5.0, 10.0))
    moving = client.until(lambda s: s.qd_actual[1] >= 0.3 - 1e-9, "at full speed")
    client.send(stopj(2.0))
    rest = client.until(lambda s: s.qd_actual[1] == 0.0, "at rest")
    braking = [r for r in rest if 0 < r.state.qd_actual[1] < 0.3 - 1e-9]
    assert braking, "the arm stopped without decelerating"
    duration = rest[-1].state.time_s - braking[0].state.time_s
    assert duration == pytest.approx(0.3 / 2.0, abs=0.01)
    assert moving[-1].state.time_s < braking[0].state.time_s
    client.close()


def test_protective_stop_at_a_joint_limit(make_sim: Callable[..., UrSimulator]) -> None:
    sim = make_sim("ur5e", initial_q=[6.2, -1.57, 1.57, -1.57, -1.57, 0.0])
    client = realtime_client(sim)
    secondary = PrimaryClient(sim.ports["secondary"])
    client.send(speedj([1.0, 0.0, 0.0, 0.0, 0.0, 0.0], 10.0, 5.0))
    stopped = client.until(
        lambda s: s.safety is SafetyMode.PROTECTIVE_STOP, "in a protective stop"
    )[-1]
    assert stopped.state.q_actual[0] <= 2 * 3.141592653589793 + 1e-9
    assert stopped.state.q_target[0] == pytest.approx(2 * 3.141592653589793)
    assert stopped.state.qd_target == (0.0,) * 6
    assert stopped.state.safety_status == float(SafetyMode.PROTECTIVE_STOP)
    deadline = time.monotonic() + DEADLINE_S
    while time.monotonic() < deadline:
        state = secondary.next_state()
        mode, board = state.robot_mode, state.masterboard
        assert mode is not None
        assert board is not None
        if mode.protective_stopped:
            assert board.safety is SafetyMode.PROTECTIVE_STOP
            break
    else:
        raise AssertionError("the secondary port never reported the protective stop")
    # Motion is refused while the stop holds ...
    refused = sim.snapshot().refused
    client.send(speedj([-0.5, 0.0, 0.0, 0.0, 0.0, 0.0], 10.0, 1.0))
    wait_for(lambda: sim.snapshot().refused == refused + 1, "the speedj refused")
    assert client.next().state.qd_actual == (0.0,) * 6
    # ... and allowed again after the unlock.
    sim.unlock_protective_stop()
    client.send(speedj([-0.5, 0.0, 0.0, 0.0, 0.0, 0.0], 10.0, 1.0))
    away = client.until(lambda s: s.q_actual[0] < 6.2, "moving away from the limit")[-1]
    assert away.state.safety is SafetyMode.NORMAL
    client.close()
    secondary.close()


def test_reconnect_after_the_controller_drops_the_connection(
    make_sim: Callable[..., UrSimulator],
) -> None:
    sim = make_sim("ur5e")
    client = realtime_client(sim)
    client.next()
    sim.drop_connections()
    with pytest.raises(ConnectionError):
        read_until_closed(client)
    client.close()
    dropped_s = time.monotonic()
    again = realtime_client(sim)
    assert again.next().state.size == 1220
    print(f"reconnected {1000 * (time.monotonic() - dropped_s):.1f} ms after the drop was seen")
    again.close()
    # Cut: connections are refused (accepted then closed at once) until restored.
    sim.cut()
    cut_client = realtime_client(sim)
    with pytest.raises((ConnectionError, OSError)):
        cut_client.next()
    cut_client.close()
    sim.restore()
    restored = realtime_client(sim)
    assert restored.next().state.size == 1220
    restored.close()


def test_mute_keeps_the_connection_and_sends_nothing(make_sim: Callable[..., UrSimulator]) -> None:
    sim = make_sim("ur5e")
    client = realtime_client(sim)
    client.next()
    sim.set_mute(True)
    client.pending.clear()
    client.sock.settimeout(0.3)
    # Drain what was in flight, then nothing more arrives for 0.3 s while muted.
    deadline = time.monotonic() + DEADLINE_S
    silent = False
    while not silent and time.monotonic() < deadline:
        try:
            data = client.sock.recv(65536)
        except TimeoutError:
            silent = True
        else:
            assert data, "the connection closed"
    assert silent, "the muted simulator kept sending"
    sim.set_mute(False)
    assert client.next().state.size == 1220
    client.close()


def test_latency_delays_commands_and_state(make_sim: Callable[..., UrSimulator]) -> None:
    sim = make_sim("ur5e", latency_ms=50.0)
    client = realtime_client(sim)
    client.next()
    sent_s = time.monotonic()
    client.send(speedj([0.0, 0.0, 0.0, 0.0, 0.0, 0.2], 10.0, 0.5))
    moving = client.until(lambda s: s.qd_actual[5] > 0.0, "moving")[-1]
    assert moving.arrived_s - sent_s >= 0.1  # 50 ms to the controller, 50 ms back


def test_garbage_is_refused_and_counted_and_the_stream_goes_on(
    make_sim: Callable[..., UrSimulator],
) -> None:
    sim = make_sim("ur5e")
    client = realtime_client(sim)
    primary = PrimaryClient(sim.ports["primary"])
    assert isinstance(decode_primary(primary.next_raw()), VersionMessage)
    before = client.next()
    garbage = [
        b"\x00\xff\xfe\x80garbage\n",
        b"set_digital_out(1, True)\n",
        b"speedj([1,2,3], 1.0, 0.1)\n",
        b"speedj([nan,0,0,0,0,0], 1.0, 0.1)\n",
        b"x" * 5000,  # no newline: dropped when it overflows the line buffer
        b"\n",
    ]  # five refused on the realtime port, the empty line ignored; one on the primary
    for chunk in garbage:
        client.send(chunk)
    primary.sock.sendall(b"movej(p[0,0,0,0,0,0])\n")
    wait_for(lambda: sim.snapshot().refused == 6, "six refusals counted")
    after = client.until(lambda s: s.time_s >= before.state.time_s + 0.2, "0.2 s later")
    times = [before.state.time_s] + [r.state.time_s for r in after]
    assert {round(b - a, 9) for a, b in itertools.pairwise(times)} == {0.002}
    assert after[-1].state.qd_actual == (0.0,) * 6
    assert sim.snapshot().accepted == 0
    # The same connection still takes a good command.
    client.send(speedj([0.0, 0.0, 0.0, 0.0, 0.0, 0.2], 10.0, 0.5))
    client.until(lambda s: s.qd_actual[5] > 0.0, "moving")
    assert sim.snapshot().accepted == 1
    assert primary.next_state().robot_mode is not None
    client.close()
    primary.close()


@pytest.mark.filterwarnings("ignore::DeprecationWarning")
@pytest.mark.parametrize(("profile", "version"), [("ur5", (3, 2, 0)), ("ur5e", (5, 10, 0))])
def test_an_independent_reader_parses_the_simulator(
    make_sim: Callable[..., UrSimulator], profile: str, version: tuple[int, int, int]
) -> None:
    """python-urx (PyPI `urx` 0.11, not ours) reads the realtime and secondary streams."""
    # In the dev extra (pyproject.toml, requirements.lock): missing, the test fails.
    from urx import urrtmon, ursecmon

    q = [0.1, -1.2, 1.3, -1.4, -1.5, 0.6]
    sim = make_sim(profile, controller_version=version, initial_q=q)
    # urx's realtime monitor connects to port 30003 itself; give it our socket instead and
    # let its own packet reader (the length, then its struct over the payload) run on it.
    monitor = urrtmon.URRTMonitor("127.0.0.1")
    monitor._rtSock.close()
    monitor._rtSock = socket.create_connection(("127.0.0.1", sim.ports["realtime"]))
    _OPEN.append(monitor._rtSock)
    ours = realtime_client(sim)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        monitor._URRTMonitor__recv_rt_data()
    data = monitor.get_all_data(wait=False)
    mine = ours.next().state
    assert list(data["qActual"]) == pytest.approx(q)
    assert list(data["qActual"]) == pytest.approx(mine.q_actual)
    assert list(data["qTarget"]) == pytest.approx(mine.q_target)
    # urx's "tcp" is the six doubles at payload index 73: the target tool pose from 3.0 on.
    assert list(data["tcp"]) == pytest.approx(mine.tool_vector_target)
    assert float(data["ctrltimestamp"]) > 0.0
    # The secondary stream: the version message and robot state, by urx's parser.
    secondary = PrimaryClient(sim.ports["secondary"])
    parser = ursecmon.ParserUtils()
    found = parser.parse(secondary.next_raw())["VersionMessage"]
    assert (found["majorVersion"], found["minorVersion"]) == version[:2]
    if version >= (3, 5, 0):
        # urx 0.11 learns the version from 38/46-byte robot mode data only; from 3.5 on the
        # sub-package is 47 bytes, so a client tells it what the version message said.
        parser.version = version[:2]
    raw = secondary.next_raw()
    assert raw[4] == PackageType.ROBOT_STATE
    parsed = parser.parse(raw)
    assert parsed["RobotModeData"]["robotMode"] == RobotMode.RUNNING
    assert parsed["RobotModeData"]["isSecurityStopped"] is False
    assert parsed["RobotModeData"]["isEmergencyStopped"] is False
    assert [parsed["JointData"][f"q_actual{i}"] for i in range(6)] == pytest.approx(q)
    assert parsed["MasterBoardData"]["robotVoltage48V"] == pytest.approx(48.0)
    assert parsed["MasterBoardData"]["masterBoardTemperature"] == pytest.approx(35.0)


def test_shipped_profiles_and_forward_kinematics(tmp_path: Path) -> None:
    names = ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint")
    for name in shipped_ur_profiles():
        profile = load_ur_profile(name)
        assert profile.joint_names[:3] == names
        assert realtime_size(profile.controller_version[:2]) in (1140, 1220)
    ur5e = load_ur_profile("ur5e")
    # The flange at all-zero joints: x = a2 + a3, y = -(d4 + d6), z = d1 - d5 (UR's DH).
    assert tcp_pose(ur5e, [0.0] * 6)[:3] == pytest.approx((-0.8172, -0.2329, 0.0628))
    assert load_ur_profile("ur3e").joints[5].max_rad is None  # wrist 3 turns without end
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "x"\nseries = "cb2"\n')
    with pytest.raises(ProfileError, match="series must be one of"):
        load_ur_profile(bad)
    with pytest.raises(ProfileError, match="not a shipped name"):
        load_ur_profile("ur99")


def test_movej_brings_every_joint_there_together(make_sim: Callable[..., UrSimulator]) -> None:
    sim = make_sim("ur5e")
    client = realtime_client(sim)
    start = client.next().state.q_actual
    goal = [start[0] + 0.4, start[1] - 0.2, start[2] + 0.1, start[3], start[4], start[5]]
    client.send(movej(goal, 2.0, 0.5))
    moving = client.until(lambda s: any(v != 0.0 for v in s.qd_actual), "moving")
    arrived = client.until(
        lambda s: (
            all(abs(s.q_actual[i] - goal[i]) < 1e-4 for i in range(6))
            and all(v == 0.0 for v in s.qd_actual)
        ),
        "at the goal and at rest",
    )
    # Synchronised: the joints' progress fractions stay together all the way.
    for received in arrived[::10]:
        fractions = [
            (received.state.q_actual[i] - start[i]) / (goal[i] - start[i]) for i in range(3)
        ]
        assert max(fractions) - min(fractions) < 0.02
    assert max(abs(r.state.qd_actual[0]) for r in arrived) <= 0.5 + 1e-9
    assert moving
    wait_for(lambda: sim.snapshot().program is None, "the movej program ended")


def test_streamed_servoj_follows_and_stops_when_the_stream_stops(
    make_sim: Callable[..., UrSimulator],
) -> None:
    sim = make_sim("ur5")  # CB3: 125 Hz
    client = realtime_client(sim)
    first = client.next().state
    q0 = list(first.q_actual)
    t, lookahead = 0.008, 0.03
    last_sent = first
    target = list(q0)
    while last_sent.time_s - first.time_s < 0.5:
        target[5] = q0[5] + 0.4 * (last_sent.time_s - first.time_s)  # 0.4 rad/s ramp
        client.send(servoj(target, t, lookahead, 300))
        last_sent = client.next().state
    rest = client.until(lambda s: s.qd_actual[5] == 0.0, "at rest")
    moved = rest[-1].state.q_actual[5] - q0[5]
    assert moved == pytest.approx(0.2, abs=0.03)  # followed the ramp, with the lookahead's lag
    assert rest[-1].state.time_s - last_sent.time_s <= t + lookahead + 0.4 / 15.0 + 0.02
    client.close()


def test_ocu_sim_dispatches_a_ur_profile() -> None:
    process = subprocess.Popen(
        [
            *(sys.executable, "-m", "ocu.sim", "--profile", "ur5", "--port-base", "0"),
            *("--exit-with-parent", "--log-level", "WARNING"),
        ],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert process.stdout is not None
        line = process.stdout.readline()
        match = re.search(r"realtime=(\d+)", line)
        assert match, line
        client = RealtimeClient(int(match[1]), 1140)  # the ur5 profile's 3.15 controller
        assert client.next().state.size == 1140
        client.close()
    finally:
        assert process.stdin is not None
        process.stdin.close()  # the parent "dies": the simulator stops by itself
        assert process.wait(timeout=DEADLINE_S) == 0
        if process.stdout is not None:
            process.stdout.close()


def test_emergency_stop_is_reported_and_refuses_motion(
    make_sim: Callable[..., UrSimulator],
) -> None:
    sim = make_sim("ur10e")
    client = realtime_client(sim)
    secondary = PrimaryClient(sim.ports["secondary"])
    client.send(speedj([0.2, 0.0, 0.0, 0.0, 0.0, 0.0], 5.0, 5.0))
    client.until(lambda s: s.qd_actual[0] > 0.0, "moving")
    sim.emergency_stop()
    stopped = client.until(lambda s: s.safety is SafetyMode.ROBOT_EMERGENCY_STOP, "e-stopped")
    assert client.next().state.qd_actual == (0.0,) * 6
    assert stopped[-1].state.size == 1220
    deadline = time.monotonic() + DEADLINE_S
    while time.monotonic() < deadline:
        mode = secondary.next_state().robot_mode
        assert mode is not None
        if mode.emergency_stopped:
            break
    else:
        raise AssertionError("the secondary port never reported the emergency stop")
    refused = sim.snapshot().refused
    client.send(speedj([0.2, 0.0, 0.0, 0.0, 0.0, 0.0], 5.0, 5.0))
    wait_for(lambda: sim.snapshot().refused == refused + 1, "the speedj refused")
    sim.emergency_stop(pressed=False)
    client.send(speedj([0.2, 0.0, 0.0, 0.0, 0.0, 0.0], 5.0, 0.2))
    assert client.until(lambda s: s.qd_actual[0] > 0.0, "moving again")[-1].state.safety is (
        SafetyMode.NORMAL
    )


def test_secondary_sends_no_version_message_before_3_1(
    make_sim: Callable[..., UrSimulator],
) -> None:
    sim = make_sim("ur5", controller_version=(3, 0, 0))
    assert realtime_client(sim).next().state.size == 1044
    secondary = PrimaryClient(sim.ports["secondary"])
    assert isinstance(decode_primary(secondary.next_raw()), RobotState)
    primary = PrimaryClient(sim.ports["primary"])
    first = decode_primary(primary.next_raw())
    assert isinstance(first, VersionMessage)
    assert first.version == (3, 0)
    mode = secondary.next_state().robot_mode
    assert mode is not None
    assert len(mode.encode()) == 38
