"""The UR link against the real UR simulator over real TCP on 127.0.0.x.

Every check reads what the SIMULATOR received and did (its snapshot: joint speeds, the running
URScript command, counters), not what the link says it sent. Waits are on conditions with
deadlines; the polling interval is not synchronisation.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
import selectors
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from ocu.link.ur import UrLink
from ocu.profile.ur import UrArmProfile, load_ur_profile
from ocu.profile.ur_robot import UR_SPEEDJ_T_S, ur_robot_profile
from ocu.records import (
    Command,
    LinkEvent,
    LinkState,
    LinkStateChanged,
    SafetyEvent,
    TelemetryFrame,
)
from ocu.sim.ur import UrSimSnapshot, UrSimulator

DEADLINE_S = 10.0
ROOT = Path(__file__).resolve().parents[2]
WRIST_3 = "wrist_3_joint"
FREEZE_S = 0.4  # over the link's freeze limit (0.3 s), under its GUI-alive timeout (0.5 s)


def wait_for(condition: Callable[[], bool], what: str, timeout_s: float = DEADLINE_S) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"not {what} within {timeout_s} s")
        time.sleep(0.001)  # polling interval: the condition decides


def at_rest(snapshot: UrSimSnapshot) -> bool:
    return all(abs(v) < 1e-9 for v in snapshot.qd)


class Events:
    """Every event but telemetry, in order, and the telemetry count."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.items: list[LinkEvent] = []
        self.telemetry: list[TelemetryFrame] = []

    def __call__(self, event: LinkEvent) -> None:
        with self._lock:
            if isinstance(event, TelemetryFrame):
                self.telemetry.append(event)
                del self.telemetry[:-5]
            else:
                self.items.append(event)

    def states(self) -> list[LinkState]:
        with self._lock:
            return [e.state for e in self.items if isinstance(e, LinkStateChanged)]

    def safety(self) -> list[str]:
        with self._lock:
            return [e.message for e in self.items if isinstance(e, SafetyEvent)]

    def last_frame(self) -> TelemetryFrame | None:
        with self._lock:
            return self.telemetry[-1] if self.telemetry else None


class Rig:
    """A simulator and a link to it, torn down by the fixture."""

    def __init__(self) -> None:
        self.sims: list[UrSimulator] = []
        self.links: list[UrLink] = []
        self.events = Events()

    def sim(self, profile: str = "ur5e", host: str = "127.0.0.1", **options: object) -> UrSimulator:
        sim = UrSimulator(load_ur_profile(profile), host=host, ports=(0, 0, 0), **options)  # type: ignore[arg-type]
        sim.start()
        self.sims.append(sim)
        return sim

    def link(
        self,
        sim: UrSimulator,
        *,
        arm: UrArmProfile | None = None,
        ports: tuple[int, int, int] | None = None,
        **options: object,
    ) -> UrLink:
        arm = arm or sim.profile
        ports = ports or (sim.ports["primary"], sim.ports["secondary"], sim.ports["realtime"])
        link = UrLink(arm, sim.host, ports=ports, listener=self.events, **options)  # type: ignore[arg-type]
        self.links.append(link)
        link.start()
        wait_for(lambda: link.state is LinkState.CONNECTED, "connected")
        return link

    def close(self) -> None:
        for link in self.links:
            link.shutdown()
        for sim in self.sims:
            sim.stop()


@pytest.fixture
def rig() -> Iterator[Rig]:
    made = Rig()
    yield made
    made.close()


def moves(sim: UrSimulator, index: int, speed: float) -> Callable[[], bool]:
    return lambda: abs(sim.snapshot().qd[index] - speed) < 1e-6


@pytest.mark.parametrize(
    ("profile", "version", "size"), [("ur5", (3, 2, 0), 1060), ("ur5e", (5, 10, 0), 1220)]
)
def test_connects_by_version_and_reports_the_joints(
    rig: Rig, profile: str, version: tuple[int, int, int], size: int
) -> None:
    sim = rig.sim(profile, host="127.0.0.2", controller_version=version)
    link = rig.link(sim, gui_alive_timeout_s=None)
    assert link.controller_version == version
    wait_for(lambda: rig.events.last_frame() is not None, "telemetry")
    frame = rig.events.last_frame()
    assert frame is not None
    names = load_ur_profile(profile).joint_names
    assert list(frame.readings) == list(names)
    q = sim.snapshot().q
    for index, name in enumerate(names):
        reading = frame.readings[name]
        assert reading.angle_rad == pytest.approx(q[index], abs=1e-6)
        assert reading.plausible
    assert frame.packet.state.size == size  # type: ignore[attr-defined]
    assert link.robot_status is None or link.robot_status.may_move


@pytest.mark.parametrize("latency_ms", [0.0, 50.0])
def test_a_command_moves_the_arm_and_a_zero_stops_it(rig: Rig, latency_ms: float) -> None:
    sim = rig.sim(latency_ms=latency_ms)
    link = rig.link(sim, gui_alive_timeout_s=None)
    link.set_command(Command({WRIST_3: 0.4, "elbow_joint": -0.2}))
    wait_for(moves(sim, 5, 0.4), "wrist 3 at 0.4 rad/s")
    assert sim.snapshot().qd[2] == pytest.approx(-0.2, abs=1e-6)
    assert sim.snapshot().program == "speedj"
    link.set_command(Command())
    wait_for(lambda: at_rest(sim.snapshot()), "the arm at rest")


def test_a_joint_with_an_end_stops_then_with_no_newer_command(rig: Rig) -> None:
    # Command.until: the position controller's motion ends where the target is, even when
    # the control thread's next tick comes late.
    sim = rig.sim()
    link = rig.link(sim, gui_alive_timeout_s=None)
    start = sim.snapshot().q[5]
    run_s = 0.4
    link.set_command(Command({WRIST_3: 0.5}, until={WRIST_3: time.monotonic() + run_s}))
    wait_for(moves(sim, 5, 0.5), "wrist 3 moving")
    wait_for(lambda: at_rest(sim.snapshot()), "the arm at rest after the end")
    assert link.command.velocity(WRIST_3) == 0.5  # what was asked: the link ended it itself
    assert sim.snapshot().q[5] - start == pytest.approx(0.5 * run_s, rel=0.5)


def test_the_round_trip_is_measured_from_the_controllers_reaction(rig: Rig) -> None:
    # 50 ms each way: the first packet whose target speeds move toward a changed speedj comes
    # at least 100 ms after it was sent; the telemetry carries it for the prediction.
    sim = rig.sim(latency_ms=50.0)
    link = rig.link(sim, gui_alive_timeout_s=None)
    assert link.stats().delay_s is None  # nothing sent yet: not measured
    for speed in (0.3, 0.0, -0.3, 0.0):  # each from steady speeds: four probes
        link.set_command(Command({WRIST_3: speed}))
        wait_for(moves(sim, 5, speed), f"wrist 3 at {speed} rad/s")
        wait_for(functools.partial(link_sees, rig, speed), "the OCU seeing it")
    delay = link.stats().delay_s
    assert delay is not None
    assert 0.1 <= delay < 0.6, delay
    frame = rig.events.last_frame()
    assert frame is not None
    assert frame.delay_s == pytest.approx(delay)


def link_sees(rig: Rig, speed: float) -> bool:
    frame = rig.events.last_frame()
    return frame is not None and abs(frame.readings[WRIST_3].speed_rad_s - speed) < 1e-3


def test_velocities_are_clamped_to_the_joints_top_speed(rig: Rig) -> None:
    sim = rig.sim()
    arm = sim.profile
    slow = dataclasses.replace(arm.joints[5], max_speed_rad_s=0.3)
    slow_arm = dataclasses.replace(arm, joints=(*arm.joints[:5], slow))
    link = rig.link(sim, arm=slow_arm, gui_alive_timeout_s=None)
    link.set_command(Command({WRIST_3: 2.0}))
    wait_for(moves(sim, 5, 0.3), "wrist 3 at its (lowered) top speed")
    # It stays there (not passing through on its way to 2 rad/s).
    accepted = sim.snapshot().accepted
    while sim.snapshot().accepted < accepted + 20:
        assert sim.snapshot().qd[5] <= 0.3 + 1e-6, "wrist 3 beyond its top speed"
        time.sleep(0.001)
    assert sim.snapshot().qd[5] == pytest.approx(0.3, abs=1e-6)
    # The simulator's own limit is 180°/s: the clamp is the link's.
    assert sim.profile.joints[5].max_speed_rad_s > 3.0


def test_emergency_stop_sends_stopj_and_the_arm_comes_to_rest(rig: Rig) -> None:
    sim = rig.sim()
    # A gentle acceleration makes the stopj's braking long enough to be seen running.
    arm = dataclasses.replace(sim.profile, max_acceleration_rad_s2=2.0)
    link = rig.link(sim, arm=arm, gui_alive_timeout_s=None)
    link.set_command(Command({WRIST_3: 1.0}))
    wait_for(moves(sim, 5, 1.0), "wrist 3 at 1 rad/s")
    link.emergency_stop("test")
    wait_for(lambda: sim.snapshot().program == "stopj", "stopj running on the controller")
    wait_for(lambda: at_rest(sim.snapshot()), "the arm at rest")
    accepted = sim.snapshot().accepted
    # The link goes on sending stopj (not motion): the arm stays at rest.
    wait_for(lambda: sim.snapshot().accepted >= accepted + 20, "20 more commands")
    assert at_rest(sim.snapshot())
    assert link.stats().estop_latched
    assert any("EMERGENCY STOP" in m for m in rig.events.safety())


def test_shutdown_sends_stopj_last(rig: Rig) -> None:
    sim = rig.sim()
    arm = dataclasses.replace(sim.profile, max_acceleration_rad_s2=2.0)
    link = rig.link(sim, arm=arm, gui_alive_timeout_s=None)
    link.set_command(Command({WRIST_3: 1.0}))
    wait_for(moves(sim, 5, 1.0), "wrist 3 at 1 rad/s")
    link.shutdown()
    assert link.state is LinkState.CLOSED
    # Braking from 1 rad/s at 2 rad/s² takes 0.5 s: stopj is seen running.
    wait_for(lambda: sim.snapshot().program == "stopj", "stopj running after shutdown")
    wait_for(lambda: at_rest(sim.snapshot()), "the arm at rest")


def test_silent_heartbeat_zeroes_the_command(rig: Rig) -> None:
    sim = rig.sim()
    link = rig.link(sim, gui_alive_timeout_s=0.2)
    link.heartbeat()
    link.set_command(Command({WRIST_3: 0.4}))
    wait_for(moves(sim, 5, 0.4), "wrist 3 moving")
    # No more heartbeats: the link zeroes by itself, and the controller stops the arm.
    wait_for(lambda: at_rest(sim.snapshot()), "the arm at rest")
    assert not link.command.is_motion
    wait_for(lambda: any("control thread silent" in m for m in rig.events.safety()), "the event")


def test_reconnects_after_a_dropped_connection_and_never_resumes(rig: Rig) -> None:
    sim = rig.sim()
    link = rig.link(sim, gui_alive_timeout_s=None)
    motion = Command({WRIST_3: 0.4})
    link.set_command(motion)
    wait_for(moves(sim, 5, 0.4), "wrist 3 moving")
    started = time.monotonic()
    sim.drop_connections()
    wait_for(
        lambda: rig.events.states()[-2:] == [LinkState.LOST, LinkState.CONNECTED], "reconnected"
    )
    reconnect_s = time.monotonic() - started
    assert rig.events.states() == [LinkState.CONNECTED, LinkState.LOST, LinkState.CONNECTED]
    assert link.connections_lost == 1
    wait_for(lambda: at_rest(sim.snapshot()), "the arm at rest")
    # Connected again: the link streams zeros; the same command set again is held at zero.
    accepted = sim.snapshot().accepted
    link.set_command(motion)
    assert not link.command.is_motion
    while sim.snapshot().accepted < accepted + 40:
        assert at_rest(sim.snapshot()), "the arm moved again after the reconnection"
        time.sleep(0.001)
    # A new command moves it.
    link.set_command(Command({WRIST_3: 0.3}))
    wait_for(moves(sim, 5, 0.3), "wrist 3 moving on a new command")
    print(f"\nreconnection: {reconnect_s * 1000:.1f} ms from the drop to CONNECTED")


def test_a_cut_controller_is_lost_and_reconnected_with_backoff(rig: Rig) -> None:
    sim = rig.sim()
    link = rig.link(sim, gui_alive_timeout_s=None)
    cut = time.monotonic()
    sim.cut()
    wait_for(lambda: link.state is LinkState.LOST, "LINK LOST")
    # Refused connections fail at once: only the backoff spaces the attempts (at once, then
    # 0.1, 0.2, 0.4 s): the fourth failure comes no sooner than 0.7 s after the cut.
    wait_for(lambda: link.failed_connects >= 4, "four failed attempts")
    assert time.monotonic() - cut >= 0.7
    assert link.connections_lost == 1
    sim.restore()
    wait_for(lambda: link.state is LinkState.CONNECTED, "connected again")


def test_a_mute_controller_is_lost_after_the_link_lost_time(rig: Rig) -> None:
    sim = rig.sim()
    link = rig.link(sim, gui_alive_timeout_s=None, link_lost_after_s=0.2)
    link.set_command(Command({WRIST_3: 0.4}))
    wait_for(moves(sim, 5, 0.4), "wrist 3 moving")
    sim.set_mute(True)
    wait_for(lambda: rig.events.states()[-1:] == [LinkState.LOST], "LINK LOST")
    reasons = [e.reason for e in rig.events.items if isinstance(e, LinkStateChanged)]
    assert "no realtime packet" in reasons[-1]
    wait_for(lambda: at_rest(sim.snapshot()), "the arm at rest")
    sim.set_mute(False)
    wait_for(lambda: link.state is LinkState.CONNECTED, "connected again")
    assert at_rest(sim.snapshot())


def test_protective_and_emergency_stops_are_reported_and_nothing_resumes(rig: Rig) -> None:
    sim = rig.sim()
    link = rig.link(sim, gui_alive_timeout_s=None)
    motion = Command({WRIST_3: 0.4})
    link.set_command(motion)
    wait_for(moves(sim, 5, 0.4), "wrist 3 moving")
    sim.emergency_stop(True)
    wait_for(
        lambda: link.robot_status is not None and link.robot_status.emergency_stopped,
        "the e-stop reported",
    )
    assert not link.command.is_motion
    wait_for(lambda: any("emergency stop" in m for m in rig.events.safety()), "the SafetyEvent")
    sim.emergency_stop(False)
    wait_for(lambda: link.robot_status is not None and link.robot_status.may_move, "released")
    accepted = sim.snapshot().accepted
    link.set_command(motion)  # the command from before the stop: held at zero
    while sim.snapshot().accepted < accepted + 30:
        assert at_rest(sim.snapshot()), "the arm resumed after the e-stop was released"
        time.sleep(0.001)
    wait_for(lambda: any("nothing resumed" in m for m in rig.events.safety()), "the SafetyEvent")


def test_a_protective_stop_at_a_joint_limit_zeroes_and_nothing_resumes(rig: Rig) -> None:
    sim = rig.sim(initial_q=[0.0, -1.57, 3.0, -1.57, -1.57, 0.0])
    link = rig.link(sim, gui_alive_timeout_s=None)
    toward_the_limit = Command({"elbow_joint": 0.5})
    link.set_command(toward_the_limit)
    wait_for(lambda: sim.snapshot().protective_stopped, "the protective stop at the elbow's limit")
    wait_for(
        lambda: link.robot_status is not None and link.robot_status.protective_stopped,
        "the protective stop reported",
    )
    assert not link.command.is_motion
    wait_for(lambda: any("protective stop" in m for m in rig.events.safety()), "the SafetyEvent")
    sim.unlock_protective_stop()
    wait_for(lambda: link.robot_status is not None and link.robot_status.may_move, "unlocked")
    accepted = sim.snapshot().accepted
    link.set_command(toward_the_limit)
    while sim.snapshot().accepted < accepted + 30:
        assert at_rest(sim.snapshot()), "the arm resumed after the protective stop"
        time.sleep(0.001)
    link.set_command(Command({"elbow_joint": -0.3}))
    wait_for(moves(sim, 2, -0.3), "the elbow moving away on a new command")


# ---- malformed bytes: a TCP proxy in front of the realtime port -----------------------------


class GarbageProxy:
    """Forwards one port both ways; `inject` puts bytes into the stream towards the client."""

    def __init__(self, host: str, upstream_port: int) -> None:
        self.upstream = (host, upstream_port)
        self.listener = socket.create_server((host, 0))
        self.port = self.listener.getsockname()[1]
        self._lock = threading.Lock()
        self._client: socket.socket | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="test-proxy", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        selector = selectors.DefaultSelector()
        selector.register(self.listener, selectors.EVENT_READ, "accept")
        pairs: dict[socket.socket, socket.socket] = {}
        try:
            while not self._stop.is_set():
                for key, _ in selector.select(0.05):
                    if key.data == "accept":
                        client, _ = self.listener.accept()
                        server = socket.create_connection(self.upstream)
                        pairs[client], pairs[server] = server, client
                        selector.register(client, selectors.EVENT_READ, "up")
                        selector.register(server, selectors.EVENT_READ, "down")
                        with self._lock:
                            self._client = client
                        continue
                    sock = key.fileobj
                    assert isinstance(sock, socket.socket)
                    try:
                        data = sock.recv(65536)
                        if data:
                            with self._lock:
                                pairs[sock].sendall(data)
                    except OSError:
                        # One end gone (the link shut down while bytes were on their way: a
                        # hog run saw "connection reset by peer" here): the proxy ends.
                        data = b""
                    if not data:
                        self._stop.set()
                        break
        finally:
            for sock in pairs:
                sock.close()
            self.listener.close()
            selector.close()

    def inject(self, data: bytes) -> None:
        with self._lock:
            assert self._client is not None
            self._client.sendall(data)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(DEADLINE_S)


def test_malformed_realtime_bytes_are_counted_and_the_link_survives(rig: Rig) -> None:
    sim = rig.sim()
    proxy = GarbageProxy(sim.host, sim.ports["realtime"])
    try:
        link = rig.link(
            sim,
            ports=(sim.ports["primary"], sim.ports["secondary"], proxy.port),
            gui_alive_timeout_s=None,
        )
        before = link.stats()
        assert before.malformed == 0
        # Plain garbage, then a frame with the right length and nonsense inside.
        proxy.inject(b"\xff" * 300)
        size = sim.realtime_size
        proxy.inject(size.to_bytes(4, "big") + b"\x7f" * (size - 4))
        wait_for(lambda: link.stats().malformed >= 2, "both counted")
        telemetry = link.stats().telemetry
        wait_for(lambda: link.stats().telemetry > telemetry + 50, "telemetry going on")
        assert link.state is LinkState.CONNECTED
        link.set_command(Command({WRIST_3: 0.4}))
        wait_for(moves(sim, 5, 0.4), "wrist 3 moving after the garbage")
    finally:
        for link in rig.links:
            link.shutdown()
        proxy.close()


# ---- SIGKILL of the OCU ----------------------------------------------------------------------


def test_sigkill_of_the_ocu_brings_the_arm_to_rest(rig: Rig) -> None:
    sim = rig.sim(host="127.0.0.3")
    speed = 0.5
    child = start_child(sim, speed)
    try:
        assert child.stdout is not None
        line = child.stdout.readline()  # the child prints within its own 10 s deadline
        assert line.strip() == "moving", line
        wait_for(moves(sim, 5, speed), "the child driving wrist 3")
        child.send_signal(signal.SIGKILL)
        killed = time.monotonic()
        wait_for(lambda: at_rest(sim.snapshot()), "the arm at rest after SIGKILL")
        rest_s = time.monotonic() - killed
        snapshot = sim.snapshot()
        controller_s = snapshot.time_s - snapshot.last_command_s
    finally:
        end_child(child)
    braking_s = speed / sim.profile.max_acceleration_rad_s2
    print(
        f"\nSIGKILL -> at rest: {rest_s * 1000:.1f} ms (wall, polled); controller time from "
        f"the last command to rest <= {controller_s * 1000:.1f} ms "
        f"(t {UR_SPEEDJ_T_S * 1000:.0f} ms + braking {braking_s * 1000:.0f} ms)"
    )
    # The robot-side watchdog: t plus the braking, plus the cycles a packet lags and polling.
    assert controller_s <= UR_SPEEDJ_T_S + braking_s + 0.1
    assert rest_s < 0.5


def start_child(sim: UrSimulator, speed: float) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    args = [sys.executable, "-m", "tests.link.ur_child", sim.host]
    args += [str(sim.ports[k]) for k in ("primary", "secondary", "realtime")]
    args += [WRIST_3, str(speed)]
    return subprocess.Popen(
        args, stdin=subprocess.PIPE, stdout=subprocess.PIPE, cwd=ROOT, env=env, text=True
    )


def end_child(child: subprocess.Popen[str]) -> None:
    child.kill()
    child.wait(DEADLINE_S)
    for stream in (child.stdin, child.stdout):
        if stream is not None:
            stream.close()


def test_a_frozen_ocu_is_stopped_by_the_controller_and_does_not_restart_it(rig: Rig) -> None:
    sim = rig.sim(host="127.0.0.4")
    child = start_child(sim, 0.5)
    try:
        assert child.stdout is not None
        assert child.stdout.readline().strip() == "moving"
        wait_for(moves(sim, 5, 0.5), "the child driving wrist 3")
        child.send_signal(signal.SIGSTOP)
        frozen = time.monotonic()
        wait_for(lambda: at_rest(sim.snapshot()), "the arm at rest (speedj's t ran out)")
        # The fault's length (not synchronisation): longer than the link's freeze limit.
        time.sleep(max(0.0, FREEZE_S - (time.monotonic() - frozen)))
        child.send_signal(signal.SIGCONT)
        accepted = sim.snapshot().accepted
        while sim.snapshot().accepted < accepted + 40:
            assert at_rest(sim.snapshot()), "the woken OCU restarted the arm"
            time.sleep(0.001)
    finally:
        end_child(child)


def test_the_robot_profile_of_a_ur() -> None:
    arm = load_ur_profile("ur10e")
    profile = ur_robot_profile(arm, "10.0.0.9")
    assert list(profile.channels) == list(arm.joint_names)
    assert [m.name for m in profile.positioned_motors] == list(arm.joint_names)
    assert profile.drive_channels is None
    assert profile.cameras == ()
    assert profile.extension is None
    assert profile.arm is not None
    assert profile.arm.joints == arm.joint_names
    assert profile.channels["shoulder_pan_joint"].hard_max == pytest.approx(math.radians(120))
    assert profile.link.address == "10.0.0.9"
    assert profile.link.robot_watchdog_s == UR_SPEEDJ_T_S
    assert profile.provenance("link.robot_watchdog_s") == "assumption"
    motor = profile.motors["elbow_joint"]
    assert motor.limits_deg == pytest.approx((-180.0, 180.0))
