"""The link's figures for the Link dock, against the real simulator over UDP: the round trip's
jitter, the scan rate, each camera's frame age, and a round trip forgotten when the link is
lost."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from ocu.link.live import UdpLink
from ocu.profile import RobotProfile
from ocu.records import CameraRequest, LinkState, LinkStats
from ocu.sim.faults import FaultConfig
from ocu.sim.simulator import RobotSimulator
from tests.link.test_core import Recorder

DEADLINE_S = 10.0


@pytest.fixture
def jittery_sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    """An extended robot behind a jittery radio: 40 ms plus 0-20 ms each way."""
    sim = RobotSimulator(
        profile,
        telemetry_hz=20.0,
        extended=True,
        faults=FaultConfig(latency_ms=40.0, jitter_ms=20.0),
        seed=7,
    )
    sim.start()
    yield sim
    sim.stop()


def test_jitter_scans_and_frame_ages_then_nothing_known_after_link_lost(
    profile: RobotProfile, jittery_sim: RobotSimulator
) -> None:
    recorder = Recorder()
    link = UdpLink(
        profile,
        jittery_sim.address,
        listener=recorder,
        extension=True,
        gui_alive_timeout_s=None,
        link_lost_after_s=1.0,
    )
    cameras = len(profile.link.camera_names)
    # Small pictures at a few frames per second: the figures, not the pictures, are tested.
    link.set_stream_request([CameraRequest(index, 64, 48, 5) for index in range(cameras)])
    link.start()

    def latest() -> LinkStats:
        return recorder.stats[-1]

    def all_known() -> bool:
        if not recorder.stats:
            return False
        stats = latest()
        return (
            stats.jitter_s is not None
            and stats.delay_s is not None
            # About 10 scans a second (the simulator's default) once the 2 s window is full.
            and stats.scan_rate_hz >= 5.0
            and len(stats.frame_age_s) == cameras
            and all(age is not None for age in stats.frame_age_s)
        )

    try:
        # Changing commands: each echo tells its own packet's round trip.
        speed = 0.2
        deadline_ticks = int(DEADLINE_S / 0.1)
        for _ in range(deadline_ticks):
            speed = -speed
            link.set_velocities(waist=speed)
            if recorder.wait(all_known, 0.1):
                break
        assert all_known(), f"figures never all known: {latest() if recorder.stats else None}"
        stats = latest()
        assert stats.delay_s is not None
        assert stats.jitter_s is not None
        # 40-60 ms each way: a round trip of about 100 ms.
        assert 0.06 < stats.delay_s < 0.3
        # The way back adds 0-20 ms, uniformly: a standard deviation of 20 / sqrt(12) = 5.8 ms,
        # plus the machine's own scheduling of both ends (45 ms once, beside two CPU hogs and
        # other test runs): seen, and of the right order.
        assert 0.003 < stats.jitter_s < 0.1
        assert stats.scan_rate_hz <= 15.0
        # Every camera streams: its newest frame is fresh.
        assert all(age is not None and 0.0 <= age < 1.5 for age in stats.frame_age_s)

        link.set_velocities(waist=0.0)
        jittery_sim.cut_link()
        assert recorder.wait(lambda: recorder.states[-1][0] == LinkState.LOST, DEADLINE_S)
        count = len(recorder.stats)
        assert recorder.wait(lambda: len(recorder.stats) > count, DEADLINE_S)
        silent = latest()
        # A round trip measured before the loss says nothing of the link that comes back.
        assert silent.delay_s is None
        assert silent.jitter_s is None
        # The frames age while nothing arrives.
        assert all(age is not None and age > 1.0 for age in silent.frame_age_s)
    finally:
        link.shutdown()
