"""Any change to zero motion goes out as a burst, as the e-stop does (issue 19, item 4).

One zero can be lost; with jitter an older motion RCP can arrive after it and drive until
the next periodic tick. The simulator (a real UDP socket) records what arrived.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from ocu.console.model import ConsoleModel
from ocu.hardware.engineer import engineer_component
from ocu.headless import HeadlessConsole
from ocu.link.live import UdpLink
from ocu.profile import RobotProfile
from ocu.sim.simulator import RobotSimulator

DEADLINE_S = 10.0


@pytest.fixture
def sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    simulator = RobotSimulator(profile, telemetry_hz=10.0, video_fps=0.0)
    simulator.start()
    yield simulator
    simulator.stop()


@pytest.fixture
def console(profile: RobotProfile, sim: RobotSimulator) -> Iterator[HeadlessConsole]:
    # The slowest periodic rate (1 Hz): the repeats cannot be mistaken for periodic ticks.
    link = UdpLink(profile, sim.address, send_rate_hz=profile.link.send_rate_min_hz)
    headless = HeadlessConsole(ConsoleModel(profile), engineer_component(link))
    headless.start()
    yield headless
    headless.stop()


def test_a_key_release_sends_the_zero_burst(
    console: HeadlessConsole, sim: RobotSimulator, profile: RobotProfile
) -> None:
    model = console.model
    assert console.call(lambda: model.hotkey_down("W", "drive_linear", 1))
    assert sim.wait_until(lambda s: s.velocities["drive_linear"] > 0, DEADLINE_S)
    before = len(sim.received_commands())
    console.call(lambda: model.hotkey_up("W"))
    repeats = profile.link.estop_repeats
    assert sim.wait_until(lambda s: s.rcp_count >= before + repeats, DEADLINE_S)
    after = sim.received_commands()[before:]
    assert all(not any(r.packet.axes) for r in after), after
    # All of them within the e-stop's window (a generous margin for a loaded machine), well
    # before the next 1 Hz tick could have sent one.
    span_s = after[repeats - 1].time_s - after[0].time_s
    assert span_s < profile.link.estop_window_s + 0.4, span_s


def test_a_slider_set_back_to_zero_sends_the_zero_burst(
    console: HeadlessConsole, sim: RobotSimulator, profile: RobotProfile
) -> None:
    model = console.model
    console.call(lambda: model.set_velocity("neck", 0.3))
    assert sim.wait_until(lambda s: s.velocities["neck"] > 0, DEADLINE_S)
    before = len(sim.received_commands())
    console.call(lambda: model.set_velocity("neck", 0.0))
    repeats = profile.link.estop_repeats
    assert sim.wait_until(lambda s: s.rcp_count >= before + repeats, DEADLINE_S)
    after = sim.received_commands()[before:]
    assert all(not any(r.packet.axes) for r in after), after
    assert after[repeats - 1].time_s - after[0].time_s < profile.link.estop_window_s + 0.4
