"""LinkCore over real UDP sockets on 127.0.0.1, with a bare socket as the robot."""

from __future__ import annotations

import random
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import pytest

from ocu.link.base import LinkError
from ocu.link.live import UdpLink
from ocu.link.stats import LossEstimator, RateMeter, tick_loss
from ocu.profile import RobotProfile
from ocu.protocol import MotorRecord, TelemetryPacket, VideoFramePacket
from ocu.protocol.mapping import CommandMapper
from ocu.protocol.wire import make_codec
from ocu.records import (
    Command,
    LinkEvent,
    LinkState,
    LinkStateChanged,
    LinkStats,
    SafetyEvent,
    TelemetryFrame,
    VideoFrame,
)
from tests.link.peer import RobotPeer

JPEG = b"\xff\xd8\xff\xe0" + b"x" * 100 + b"\xff\xd9"


class Recorder:
    """Collects every link event (a listener); tests wait on it with deadlines."""

    def __init__(self) -> None:
        self.cond = threading.Condition()
        self.telemetry: list[TelemetryFrame] = []
        self.video: list[VideoFrame] = []
        self.states: list[tuple[LinkState, str]] = []
        self.safety: list[str] = []
        self.stats: list[LinkStats] = []
        self.events: list[LinkEvent] = []

    def __call__(self, event: LinkEvent) -> None:
        with self.cond:
            self.events.append(event)
            if isinstance(event, TelemetryFrame):
                self.telemetry.append(event)
            elif isinstance(event, VideoFrame):
                self.video.append(event)
            elif isinstance(event, LinkStateChanged):
                self.states.append((event.state, event.reason))
            elif isinstance(event, SafetyEvent):
                self.safety.append(event.message)
            elif isinstance(event, LinkStats):
                self.stats.append(event)
            self.cond.notify_all()

    def wait(self, predicate: Callable[[], bool], timeout_s: float = 3.0) -> bool:
        with self.cond:
            return self.cond.wait_for(predicate, timeout_s)


@pytest.fixture
def peer(profile: RobotProfile) -> Iterator[RobotPeer]:
    robot = RobotPeer(profile)
    yield robot
    robot.close()


def make_link(profile: RobotProfile, peer: RobotPeer, **kwargs: Any) -> tuple[UdpLink, Recorder]:
    recorder = Recorder()
    link = UdpLink(profile, peer.address, listener=recorder, **kwargs)
    return link, recorder


def wait_for(predicate: Callable[[], bool], timeout_s: float = 3.0) -> bool:
    """Poll a condition that has no signal of its own (stats counters) with a deadline."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.002)
    return predicate()


def test_command_change_is_sent_at_once_not_on_the_tick(
    profile: RobotProfile, peer: RobotPeer
) -> None:
    link, _ = make_link(profile, peer, send_rate_hz=1.0)
    link.start()
    try:
        peer.recv_rcp()  # the first tick goes out at start
        link.set_velocities(drive_linear=0.25)
        changed = time.monotonic()
        packet, arrived, _ = peer.recv_rcp(timeout_s=0.5)
        axis = profile.channels["drive_linear"].axis
        assert packet.axes[axis] == round(0.25 * profile.linear_axis_per_m_s)
        assert arrived - changed < 0.1  # the 1 Hz tick would take up to a second
    finally:
        link.shutdown()


def test_unchanged_command_is_not_resent_early(profile: RobotProfile, peer: RobotPeer) -> None:
    link, _ = make_link(profile, peer, send_rate_hz=1.0)
    link.start()
    try:
        peer.recv_rcp()
        link.set_command(link.command)
        with pytest.raises(TimeoutError):
            peer.recv_rcp(timeout_s=0.3)
    finally:
        link.shutdown()


def test_periodic_rate_and_runtime_change(profile: RobotProfile, peer: RobotPeer) -> None:
    link, _ = make_link(profile, peer, send_rate_hz=5.0)
    link.start()
    try:
        peer.recv_rcp()
        first = time.monotonic()
        for _ in range(5):
            peer.recv_rcp()
        assert 0.8 < time.monotonic() - first < 1.3  # five more at 5 Hz take about a second
        link.set_rate_hz(50.0)
        peer.recv_rcp()
        start = time.monotonic()
        for _ in range(25):
            peer.recv_rcp()
        assert time.monotonic() - start < 0.8
    finally:
        link.shutdown()


@pytest.mark.parametrize("rate", [0.5, 51.0, float("nan")])
def test_rate_outside_profile_bounds_is_refused(
    profile: RobotProfile, peer: RobotPeer, rate: float
) -> None:
    link, _ = make_link(profile, peer)
    try:
        with pytest.raises(ValueError, match="send rate must be within 1-50 Hz"):
            link.set_rate_hz(rate)
    finally:
        link.shutdown()


def test_commands_are_clamped_to_the_hard_maximum(profile: RobotProfile, peer: RobotPeer) -> None:
    # The operator's current maxima are the console model's; the link holds the profile's.
    link, _ = make_link(profile, peer, send_rate_hz=1.0)
    link.start()
    try:
        peer.recv_rcp()
        link.set_velocities(waist=-5.0)
        waist = profile.channels["waist"]
        packet, _ = peer.recv_until(lambda p: p.axes[waist.axis] != 0)
        assert packet.axes[waist.axis] == -round(waist.hard_max * waist.axis_per_unit)
    finally:
        link.shutdown()


def test_telemetry_from_robot_is_decoded_and_connects(
    profile: RobotProfile, peer: RobotPeer
) -> None:
    link, recorder = make_link(profile, peer)
    link.start()
    try:
        peer.send_telemetry(link.address)
        assert recorder.wait(lambda: len(recorder.telemetry) == 1)
        frame = recorder.telemetry[0]
        assert frame.packet.tick == peer.tick
        assert "waist" in frame.readings
        assert recorder.wait(
            lambda: (
                (LinkState.CONNECTED, f"packets from {peer.address[0]}:{peer.address[1]}")
                in recorder.states
            )
        )
        peer.send_raw(make_codec(profile).encode(VideoFramePacket(JPEG)), link.address)
        assert recorder.wait(lambda: len(recorder.video) == 1)
        assert recorder.video[0].jpeg == JPEG
    finally:
        link.shutdown()


def test_foreign_source_is_ignored(profile: RobotProfile, peer: RobotPeer) -> None:
    link, recorder = make_link(profile, peer)
    link.start()
    stranger = RobotPeer(profile)
    try:
        for _ in range(10):
            stranger.send_telemetry(link.address)
        peer.send_telemetry(link.address)  # one from the robot, as a marker
        assert recorder.wait(lambda: len(recorder.telemetry) == 1)
        assert wait_for(lambda: link.stats().foreign == 10)
        assert link.stats().received == 1
        assert recorder.telemetry[0].packet.tick == peer.tick
    finally:
        stranger.close()
        link.shutdown()


def test_malformed_datagrams_are_counted_and_dropped(
    profile: RobotProfile, peer: RobotPeer
) -> None:
    link, recorder = make_link(profile, peer)
    link.start()
    codec = make_codec(profile)
    good = codec.encode(TelemetryPacket(tick=5, motors=(MotorRecord(device_id=4),)))
    bad = [
        b"",
        b"\x02",
        good[:-1],
        good + b"\0",
        b"\x7f" + good[1:],
        good[:9] + b"\x0b" + good[10:],  # motor count 11
        b"\x03" + b"not a jpeg",
        b"\x03\xff\xd8\xff truncated",
    ]
    try:
        for data in bad:
            peer.send_raw(data, link.address)
        peer.send_raw(good, link.address)
        assert recorder.wait(lambda: len(recorder.telemetry) == 1)
        assert wait_for(lambda: link.stats().malformed == len(bad))
    finally:
        link.shutdown()


def test_hundred_thousand_random_datagrams_are_all_counted(
    profile: RobotProfile, peer: RobotPeer
) -> None:
    link, _ = make_link(profile, peer, link_lost_after_s=60.0)
    link.start()
    stranger = RobotPeer(profile)
    rng = random.Random(1234)
    frame_types = [0x01, 0x02, 0x03, 0x00, 0xFF]
    total = 100_000
    batch = 250
    try:
        sent = 0
        while sent < total:
            for _ in range(batch):
                kind = rng.random()
                if kind < 0.3:
                    size = rng.choice([275, 57, 274, 276, 1])
                    data = bytes([rng.choice(frame_types)]) + rng.randbytes(size - 1)
                elif kind < 0.4:
                    data = b"\x03\xff\xd8\xff" + rng.randbytes(rng.randrange(0, 200)) + b"\xff\xd9"
                else:
                    data = rng.randbytes(rng.randrange(0, 600))
                sender = stranger if rng.random() < 0.1 else peer
                sender.send_raw(data, link.address)
                sent += 1

            def all_counted(expected: int = sent) -> bool:
                s = link.stats()
                return s.received + s.malformed + s.foreign == expected

            # Pace the batches so the kernel's receive buffer never overflows.
            assert wait_for(all_counted, 10.0), link.stats()
        stats = link.stats()
        assert stats.foreign > 0
        assert stats.malformed > 0
        assert link.state in (LinkState.CONNECTED, LinkState.CONNECTING)
    finally:
        stranger.close()
        link.shutdown()


def test_link_lost_zeroes_motion_and_recovers(profile: RobotProfile, peer: RobotPeer) -> None:
    link, recorder = make_link(profile, peer, link_lost_after_s=0.3, gui_alive_timeout_s=None)
    link.start()
    try:
        peer.send_telemetry(link.address)
        assert recorder.wait(lambda: any(s == LinkState.CONNECTED for s, _ in recorder.states))
        link.set_velocities(drive_linear=0.3)
        lost_at = time.monotonic()
        assert recorder.wait(lambda: any(s == LinkState.LOST for s, _ in recorder.states))
        assert time.monotonic() - lost_at >= 0.25
        assert not link.command.is_motion
        assert recorder.wait(lambda: "link lost: motion commands zeroed" in recorder.safety)
        axis = profile.channels["drive_linear"].axis
        peer.recv_until(lambda p: p.axes[axis] == 0)
        peer.send_telemetry(link.address)
        assert recorder.wait(lambda: recorder.states[-1][0] == LinkState.CONNECTED)
        assert not link.command.is_motion  # recovery does not resume motion by itself
    finally:
        link.shutdown()


def test_no_answer_at_all_is_reported_as_lost(profile: RobotProfile, peer: RobotPeer) -> None:
    link, recorder = make_link(profile, peer, link_lost_after_s=0.2)
    link.start()
    try:
        assert recorder.wait(lambda: any(s == LinkState.LOST for s, _ in recorder.states))
    finally:
        link.shutdown()


def test_silent_gui_thread_zeroes_motion(profile: RobotProfile, peer: RobotPeer) -> None:
    link, recorder = make_link(profile, peer, link_lost_after_s=60.0)
    link.start()
    axis = profile.channels["shoulder"].axis
    try:
        link.set_velocities(shoulder=0.3)
        set_at = time.monotonic()
        peer.recv_until(lambda p: p.axes[axis] != 0)
        _, zero_at = peer.recv_until(lambda p: p.axes[axis] == 0, timeout_s=2.0)
        assert 0.45 < zero_at - set_at < 0.8
        assert recorder.wait(lambda: any("control thread silent" in m for m in recorder.safety))
    finally:
        link.shutdown()


def test_heartbeats_keep_motion_going(profile: RobotProfile, peer: RobotPeer) -> None:
    link, recorder = make_link(profile, peer, link_lost_after_s=60.0, send_rate_hz=20.0)
    link.start()
    axis = profile.channels["shoulder"].axis
    try:
        link.set_velocities(shoulder=0.3)
        peer.recv_until(lambda p: p.axes[axis] != 0)
        end = time.monotonic() + 1.2
        while time.monotonic() < end:
            link.heartbeat()
            packet, _, _ = peer.recv_rcp()
            assert packet.axes[axis] != 0
        assert recorder.safety == []
    finally:
        link.shutdown()


def test_estop_is_sent_at_once_and_repeated_as_a_burst(
    profile: RobotProfile, peer: RobotPeer
) -> None:
    # At once and as a burst, not at the link's send rate (1 Hz here): the whole burst comes
    # within half a period. How soon in milliseconds is bench/bench_link.py's to measure (a
    # loaded machine once made the last repeat 52 ms late against a 50 ms assertion here).
    link, recorder = make_link(profile, peer, send_rate_hz=1.0)
    link.start()
    axis = profile.channels["drive_linear"].axis
    try:
        link.set_velocities(drive_linear=0.3)
        peer.recv_until(lambda p: p.axes[axis] != 0)
        peer.drain()
        link.emergency_stop()
        stopped = time.monotonic()
        arrivals = []
        for _ in range(profile.link.estop_repeats):
            packet, arrived, _ = peer.recv_rcp(timeout_s=0.5)
            assert packet.axes == (0,) * 16
            arrivals.append(arrived)
        assert arrivals[-1] - stopped < 0.5
        assert link.stats().estop_latched
        assert any("EMERGENCY STOP" in m for m in recorder.safety)
    finally:
        link.shutdown()


def test_estop_keeps_torch_and_new_motion_clears_latch(
    profile: RobotProfile, peer: RobotPeer
) -> None:
    link, _ = make_link(profile, peer, send_rate_hz=1.0)
    link.start()
    try:
        link.set_command(Command({"waist": 0.2}, torch=True))
        link.emergency_stop()
        assert link.command == Command({}, torch=True)
        assert link.stats().estop_latched
        link.set_velocities(waist=0.1)
        assert not link.stats().estop_latched
    finally:
        link.shutdown()


def test_shutdown_is_idempotent_and_sends_zeros_last(
    profile: RobotProfile, peer: RobotPeer
) -> None:
    link, recorder = make_link(profile, peer, send_rate_hz=50.0)
    link.start()
    link.set_velocities(elbow=0.3)
    link.shutdown()
    link.shutdown()
    packets = []
    while True:
        try:
            packets.append(peer.recv_rcp(timeout_s=0.2)[0])
        except TimeoutError:
            break
    assert packets
    assert packets[-1].axes == (0,) * 16
    assert recorder.states[-1][0] == LinkState.CLOSED


def test_faulty_listener_does_not_stop_the_link(profile: RobotProfile, peer: RobotPeer) -> None:
    class Broken(Recorder):
        def __call__(self, event: LinkEvent) -> None:
            super().__call__(event)
            if isinstance(event, TelemetryFrame):
                raise RuntimeError("listener bug")

    recorder = Broken()
    link = UdpLink(profile, peer.address, listener=recorder)
    link.start()
    try:
        peer.send_telemetry(link.address)
        peer.send_telemetry(link.address)
        assert recorder.wait(lambda: len(recorder.telemetry) == 2)
        peer.recv_rcp()  # still sending
    finally:
        link.shutdown()


def test_stats_report_loss_from_tick_gaps(profile: RobotProfile, peer: RobotPeer) -> None:
    link, recorder = make_link(profile, peer)
    link.start()
    try:
        # One gap of two missing packets; sent at once, so the ticks stay within what the
        # robot's clock can run between arrivals (a jump further ahead is junk: test_junk).
        for step in [100, 100, 300, 100, 100]:
            peer.send_telemetry(link.address, tick_step=step)
        assert recorder.wait(lambda: len(recorder.telemetry) == 5)
        loss = link.stats().loss_estimate
        assert loss == pytest.approx(2 / 7)
    finally:
        link.shutdown()


def test_loss_estimator_duplicates_and_reordering() -> None:
    estimator = LossEstimator(window_s=100.0)
    assert estimator.loss(0.0) is None
    ticks = [100, 200, 200, 300, 500, 400, 700, 800, 900, 1000, 1300]
    for t, tick in enumerate(ticks):
        estimator.add(tick, float(t))
    window = estimator.window(11.0)
    assert estimator.duplicates == 1
    assert estimator.reordered == 1  # 400 after 500: late, but it did arrive
    assert window.period_ticks == 100.0
    assert window.lost == 3  # 600, 1100 and 1200
    assert estimator.loss(11.0) == pytest.approx(3 / 13)
    assert estimator.loss(200.0) is None  # nothing left in the window


def test_loss_estimator_ignores_jitter() -> None:
    # Ticks 50 apart with one packet 34 ms late: a short step must not shrink the period.
    estimator = LossEstimator(window_s=100.0)
    for t, tick in enumerate([0, 51, 135, 153, 200, 250, 300, 350, 400]):
        estimator.add(tick, float(t))
    assert estimator.loss(9.0) == 0.0


@pytest.mark.parametrize("loss", [0.1, 0.3, 0.6])
def test_tick_loss_matches_dropped_share(loss: float) -> None:
    rng = random.Random(3)
    sent = [i * 1000 + rng.randint(-100, 100) for i in range(2000)]  # 10% send jitter
    received = [t for t in sent if rng.random() >= loss]
    result = tick_loss(received)
    assert result.fraction == pytest.approx(loss, abs=0.03)


def test_rate_meter_window() -> None:
    meter = RateMeter(window_s=2.0)
    for i in range(10):
        meter.add(i * 0.2)
    assert meter.rate(1.8) == pytest.approx(5.0)
    assert meter.rate(10.0) == 0.0


def test_rcp_encoding_matches_mapper(profile: RobotProfile, peer: RobotPeer) -> None:
    link, _ = make_link(profile, peer, send_rate_hz=1.0)
    link.start()
    try:
        peer.recv_rcp()
        command = Command({"neck": -0.3, "gripper": 0.1}, torch=True, camera=3)
        link.set_command(command)
        packet, _, source = peer.recv_rcp()
        assert packet == CommandMapper(profile).to_packet(command)
        assert source == link.address
    finally:
        link.shutdown()


def test_unresolvable_robot_host_gives_clear_error(profile: RobotProfile) -> None:
    with pytest.raises(LinkError, match=r"cannot resolve robot host 'no-such-host\.invalid'"):
        UdpLink(profile, ("no-such-host.invalid", 10000))


def test_commands_from_another_thread_do_not_hide_a_silent_owner(
    profile: RobotProfile, peer: RobotPeer
) -> None:
    link, recorder = make_link(profile, peer, link_lost_after_s=60.0, send_rate_hz=20.0)
    link.start()
    axis = profile.channels["drive_linear"].axis
    stop = threading.Event()

    def bridge() -> None:
        # Like a ROS bridge hosted by the GUI: a steady stream of commands from its thread.
        while not stop.wait(0.05):
            link.set_velocities(drive_linear=0.3)

    try:
        link.heartbeat()  # this thread owns the commands ... and then falls silent
        streamer = threading.Thread(target=bridge, name="test-bridge")
        streamer.start()
        peer.recv_until(lambda p: p.axes[axis] != 0)
        assert recorder.wait(lambda: any("control thread silent" in m for m in recorder.safety))
        peer.drain()
        for _ in range(10):  # half a second of 20 Hz ticks and bridge commands: all still
            assert peer.recv_rcp()[0].axes[axis] == 0
        link.heartbeat()  # the owner is back: the bridge may drive again
        peer.recv_until(lambda p: p.axes[axis] != 0)
    finally:
        stop.set()
        streamer.join()
        link.shutdown()
