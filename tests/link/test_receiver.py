"""The link's receiver under field conditions: late, duplicated and impossible telemetry,
the delay it measures, and no motion while the link is lost (real sockets on 127.0.0.1)."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator

import pytest

from ocu.link.live import UdpLink
from ocu.profile import RobotProfile
from ocu.protocol import MotorRecord, TelemetryPacket
from ocu.protocol.mapping import rad_to_ticks
from ocu.records import LinkState
from ocu.sim.faults import FaultConfig
from ocu.sim.simulator import RobotSimulator
from tests.link.peer import RobotPeer
from tests.link.test_core import Recorder, make_link, wait_for

SHOULDER_ID = 5


@pytest.fixture
def peer(profile: RobotProfile) -> Iterator[RobotPeer]:
    robot = RobotPeer(profile)
    yield robot
    robot.close()


def send(peer: RobotPeer, link: UdpLink, tick: int, shoulder_raw: int) -> None:
    record = MotorRecord(device_id=SHOULDER_ID, position=shoulder_raw)
    peer.send_raw(peer.codec.encode(TelemetryPacket(tick=tick, motors=(record,))), link.address)


def test_late_and_repeated_telemetry_never_reaches_the_listeners(
    profile: RobotProfile, peer: RobotPeer
) -> None:
    link, recorder = make_link(profile, peer, gui_alive_timeout_s=None)
    raw = rad_to_ticks(profile.motors["shoulder"], 0.5)
    link.start()
    try:
        for tick in (20_000, 20_200, 20_100, 20_200, 20_300):
            send(peer, link, tick, raw)
        assert recorder.wait(lambda: len(recorder.telemetry) == 3)
        assert wait_for(lambda: link.stats().stale_telemetry == 2)
        assert [f.packet.tick for f in recorder.telemetry] == [20_000, 20_200, 20_300]
        # A robot that restarted (ticks 20 s back) counts from zero again: believed once a
        # second packet agrees (a lone far-off tick is junk: tests/link/test_junk.py).
        send(peer, link, 5, raw)
        send(peer, link, 105, raw)
        assert recorder.wait(lambda: len(recorder.telemetry) == 4)
        assert recorder.telemetry[-1].packet.tick == 105
        assert wait_for(lambda: link.stats().stale_telemetry == 3)
        assert link.stats().malformed == 0
    finally:
        link.shutdown()


def test_impossible_readings_carry_their_fault(profile: RobotProfile, peer: RobotPeer) -> None:
    link, recorder = make_link(profile, peer, gui_alive_timeout_s=None)
    link.start()
    try:
        send(peer, link, 1000, rad_to_ticks(profile.motors["shoulder"], math.radians(30)))
        send(peer, link, 2000, 0)
        assert recorder.wait(lambda: len(recorder.telemetry) == 2)
        good, bad = (frame.readings["shoulder"] for frame in recorder.telemetry)
        assert good.plausible
        assert not bad.plausible
        assert bad.fault is not None
        assert "raw position 0x00000000" in bad.fault
        assert recorder.telemetry[1].faults == {"shoulder": bad.fault}
    finally:
        link.shutdown()


def test_no_motion_leaves_while_the_link_is_lost(profile: RobotProfile, peer: RobotPeer) -> None:
    link, recorder = make_link(profile, peer, link_lost_after_s=0.3, gui_alive_timeout_s=None)
    axis = profile.channels["drive_linear"].axis
    link.start()
    try:
        peer.send_telemetry(link.address)
        assert recorder.wait(lambda: any(s == LinkState.CONNECTED for s, _ in recorder.states))
        assert recorder.wait(lambda: any(s == LinkState.LOST for s, _ in recorder.states))
        peer.drain()
        link.set_velocities(drive_linear=0.3)  # e.g. a ROS planner still streaming cmd_vel
        assert not link.command.is_motion
        deadline = time.monotonic() + 0.5  # the periodic tick sends several RCPs meanwhile
        while time.monotonic() < deadline:
            packet, _, _ = peer.recv_rcp(1.0)
            assert packet.axes[axis] == 0
        peer.send_telemetry(link.address)
        assert recorder.wait(lambda: recorder.states[-1][0] == LinkState.CONNECTED)
        link.set_velocities(drive_linear=0.3)  # an operator's new command after recovery
        peer.recv_until(lambda p: p.axes[axis] > 0)
    finally:
        link.shutdown()


@pytest.mark.parametrize("latency_ms", [0.0, 100.0])
def test_the_round_trip_is_measured(profile: RobotProfile, latency_ms: float) -> None:
    sim = RobotSimulator(
        profile, telemetry_hz=20.0, video_fps=0.0, faults=FaultConfig(latency_ms=latency_ms)
    )
    sim.start()
    recorder = Recorder()
    link = UdpLink(profile, sim.address, listener=recorder, gui_alive_timeout_s=None)
    link.start()
    try:
        assert recorder.wait(lambda: len(recorder.telemetry) >= 2)
        # Position control changes the speed often: every change is a time mark.
        start = time.monotonic()
        while time.monotonic() - start < 1.5:
            speed = 0.1 + 0.05 * (int((time.monotonic() - start) * 20) % 4)
            link.set_velocities(shoulder=speed)
            time.sleep(0.05)  # the pace of a control loop, not a synchronisation
        link.set_velocities(shoulder=0.0)
        delay = link.stats().delay_s
        assert delay is not None
        assert delay == pytest.approx(2 * latency_ms / 1000, abs=0.035)
        measured = [f.delay_s for f in recorder.telemetry[-5:]]
        assert all(d is not None and abs(d - 2 * latency_ms / 1000) < 0.06 for d in measured)
    finally:
        link.shutdown()
        sim.stop()
