"""The commands lost on the way to the robot: the estimator from the robot's echoes (no
sockets), then the live link against the extended simulator over UDP."""

from __future__ import annotations

import pytest

from ocu.link.live import UdpLink
from ocu.link.stats import UplinkLossEstimator
from ocu.profile import RobotProfile
from ocu.records import LinkStats
from ocu.sim.faults import FaultConfig
from ocu.sim.simulator import RobotSimulator
from tests.link.test_core import Recorder

DEADLINE_S = 20.0


def test_the_share_not_applied_between_the_windows_echoes() -> None:
    estimator = UplinkLossEstimator(window_s=30.0)
    assert estimator.loss(0.0) is None
    estimator.add(100, 50, 0.0)
    assert estimator.loss(0.0) is None  # one echo says nothing yet
    estimator.add(100, 50, 0.2)
    assert estimator.loss(0.2) is None  # no RCP sent between
    estimator.add(200, 125, 1.0)  # 100 sent, 75 applied
    assert estimator.loss(1.0) == pytest.approx(0.25)
    estimator.add(300, 225, 2.0)  # 200 sent, 175 applied
    assert estimator.loss(2.0) == pytest.approx(0.125)


def test_an_echo_reordered_on_its_way_is_left_out() -> None:
    estimator = UplinkLossEstimator()
    estimator.add(1000, 500, 0.0)
    estimator.add(1100, 590, 1.0)
    estimator.add(1090, 585, 1.1)  # an older status packet, arriving late
    assert estimator.loss(1.1) == pytest.approx(0.1)
    estimator.add(1200, 695, 2.0)  # late RCPs counted as they come: a little ahead is fine
    assert estimator.loss(2.0) == pytest.approx(0.025)


def test_counters_wrap_and_old_echoes_leave_the_window() -> None:
    estimator = UplinkLossEstimator(window_s=10.0)
    estimator.add(2**32 - 50, 2**32 - 10, 0.0)
    estimator.add(50, 80, 5.0)  # 100 sent, 90 applied, both across the wrap
    assert estimator.loss(5.0) == pytest.approx(0.1)
    estimator.add(150, 180, 20.0)  # the first leaves; the second is the window's base
    assert estimator.loss(20.0) == pytest.approx(0.0)


def test_a_new_sequence_starts_the_window_over() -> None:
    estimator = UplinkLossEstimator()
    estimator.add(1000, 500, 0.0)
    estimator.add(1100, 550, 1.0)
    assert estimator.loss(1.0) == pytest.approx(0.5)
    estimator.add(7, 560, 2.0)  # the OCU restarted its numbers: behind the newest
    assert estimator.loss(2.0) is None
    estimator.add(107, 660, 3.0)
    assert estimator.loss(3.0) == pytest.approx(0.0)
    estimator.add(117, 3, 4.0)  # the robot's count went back: it restarted
    assert estimator.loss(4.0) is None
    estimator.reset()
    assert estimator.loss(4.0) is None


def _settled_uplink(profile: RobotProfile, sim: RobotSimulator, *, extension: bool) -> LinkStats:
    """The link's statistics once 150 RCPs went out at 20 Hz (about 8 s)."""
    recorder = Recorder()
    link = UdpLink(
        profile,
        sim.address,
        listener=recorder,
        extension=extension,
        gui_alive_timeout_s=None,
        send_rate_hz=20.0,
    )
    link.start()
    try:
        assert recorder.wait(
            lambda: bool(recorder.stats) and recorder.stats[-1].sent >= 150, DEADLINE_S
        )
        return recorder.stats[-1]
    finally:
        link.shutdown()


@pytest.mark.parametrize("loss", [0.0, 0.3])
def test_an_extended_robot_tells_the_commands_lost(profile: RobotProfile, loss: float) -> None:
    sim = RobotSimulator(
        profile, telemetry_hz=10.0, video_fps=0.0, extended=True, faults=FaultConfig(loss=loss)
    )
    sim.start()
    try:
        stats = _settled_uplink(profile, sim, extension=True)
    finally:
        sim.stop()
    assert stats.uplink_loss is not None
    # About 150 RCPs: the share lost is known to within a few per cent.
    assert stats.uplink_loss == pytest.approx(loss, abs=0.12)


def test_a_vendor_robot_cannot_tell(profile: RobotProfile) -> None:
    sim = RobotSimulator(profile, telemetry_hz=10.0, video_fps=0.0)
    sim.start()
    try:
        stats = _settled_uplink(profile, sim, extension=True)
    finally:
        sim.stop()
    assert stats.uplink_loss is None


def test_commands_reordered_or_duplicated_by_the_link_are_not_counted_lost(
    profile: RobotProfile,
) -> None:
    # 200 ms of jitter at 20 Hz reorders most RCPs: the robot drops the late ones, but they
    # reached it, and the link lost nothing.
    faults = FaultConfig(jitter_ms=200.0, duplicate=0.5)
    sim = RobotSimulator(profile, telemetry_hz=10.0, video_fps=0.0, extended=True, faults=faults)
    sim.start()
    try:
        stats = _settled_uplink(profile, sim, extension=True)
        dropped_late = sim.state().stale_rcp_count
    finally:
        sim.stop()
    assert dropped_late > 10  # the condition this test is about did happen
    assert stats.uplink_loss is not None
    assert stats.uplink_loss == pytest.approx(0.0, abs=0.12)
