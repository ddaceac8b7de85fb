"""The link against the real simulator: e-stop under loss, link loss and recovery, the Qt thread."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from ocu.link.live import UdpLink
from ocu.profile import RobotProfile
from ocu.records import LinkState
from ocu.sim.faults import FaultConfig
from ocu.sim.simulator import RobotSimulator
from tests.link.test_core import Recorder


@pytest.fixture
def lossy_sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    sim = RobotSimulator(
        profile, telemetry_hz=10.0, video_fps=0.0, faults=FaultConfig(loss=0.3), seed=42
    )
    sim.start()
    yield sim
    sim.stop()


def test_estop_burst_stops_the_robot_under_30_percent_loss(
    profile: RobotProfile, lossy_sim: RobotSimulator
) -> None:
    # A slow tick, so only the burst itself can stop the robot within the deadline.
    link = UdpLink(profile, lossy_sim.address, gui_alive_timeout_s=None, send_rate_hz=1.0)
    link.start()
    stopped_by_burst = 0
    trials = 40
    try:
        for _ in range(trials):
            link.set_velocities(drive_linear=0.3)
            assert lossy_sim.wait_until(lambda s: not s.all_stopped, 3.0)
            link.emergency_stop("test")
            # 50 ms: the burst's window plus margin; the next 1 Hz tick comes much later.
            if lossy_sim.wait_until(lambda s: s.all_stopped, 0.06):
                stopped_by_burst += 1
            assert lossy_sim.wait_until(lambda s: s.all_stopped, 2.0)
    finally:
        link.shutdown()
    # Each burst is lost whole with probability 0.3**5 = 0.24%; allow one such event.
    assert stopped_by_burst >= trials - 1
    assert lossy_sim.state().dropped_to_robot > 0


def test_cut_link_is_lost_then_recovers(profile: RobotProfile) -> None:
    sim = RobotSimulator(profile, telemetry_hz=20.0, video_fps=0.0)
    sim.start()
    recorder = Recorder()
    link = UdpLink(
        profile, sim.address, listener=recorder, link_lost_after_s=0.4, gui_alive_timeout_s=None
    )
    link.start()
    try:
        assert recorder.wait(lambda: any(s == LinkState.CONNECTED for s, _ in recorder.states))
        link.set_velocities(waist=0.3)
        assert sim.wait_until(lambda s: s.velocities["waist"] != 0.0, 2.0)
        sim.cut_link()
        assert recorder.wait(lambda: recorder.states[-1][0] == LinkState.LOST, 3.0)
        assert not link.command.is_motion
        # The robot's own watchdog stops it while the link is cut.
        assert sim.wait_until(lambda s: s.watchdog_stopped and s.all_stopped, 3.0)
        sim.restore_link()
        assert recorder.wait(lambda: recorder.states[-1][0] == LinkState.CONNECTED, 3.0)
        assert sim.wait_until(lambda s: s.rcp_count > 0 and not s.watchdog_stopped, 3.0)
        assert sim.state().velocities["waist"] == 0.0  # recovery resumes no motion
    finally:
        link.shutdown()
        sim.stop()
