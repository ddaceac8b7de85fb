"""One Link interface, two live backends: the same behaviour over UDP and over a virtual wire.

Both run against the real simulator (over a UDP socket on 127.0.0.1, or the robot end of an
in-process VirtualWire), so everything from the codec to the robot's physics is the real thing.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from ocu.link.base import Link
from ocu.link.live import UdpLink, VirtualLink
from ocu.net.transport import VIRTUAL_OCU, VirtualWire
from ocu.profile import RobotProfile
from ocu.records import LinkState
from ocu.sim.simulator import RobotSimulator
from tests.record.helpers import Collector

DEADLINE_S = 5.0


@pytest.fixture(params=["udp", "virtual"])
def robot_and_link(
    request: pytest.FixtureRequest, profile: RobotProfile
) -> Iterator[tuple[RobotSimulator, Link, Collector]]:
    wire = VirtualWire() if request.param == "virtual" else None
    sim = RobotSimulator(
        profile,
        transport=wire.robot if wire is not None else None,
        telemetry_hz=20.0,
        video_fps=10.0,
        video_size=(160, 120),
        seed=3,
    )
    sim.start()
    events = Collector()
    link: Link
    if wire is not None:
        link = VirtualLink(profile, wire.ocu, listener=events, gui_alive_timeout_s=None)
    else:
        link = UdpLink(profile, sim.address, listener=events, gui_alive_timeout_s=None)
    try:
        yield sim, link, events
    finally:
        link.shutdown()
        sim.stop()
        if wire is not None:
            wire.close()


def test_a_live_link_commands_and_reports_the_same_over_either_backend(
    robot_and_link: tuple[RobotSimulator, Link, Collector],
) -> None:
    sim, link, events = robot_and_link
    assert not link.read_only
    link.start()
    assert events.wait(lambda: LinkState.CONNECTED in events.states, DEADLINE_S)
    assert link.state == LinkState.CONNECTED
    assert events.wait(lambda: len(events.telemetry) >= 3 and bool(events.video), DEADLINE_S)
    assert "waist" in events.telemetry[-1].readings

    link.set_velocities(waist=0.3)
    assert sim.wait_until(lambda s: s.velocities["waist"] > 0.0, DEADLINE_S)
    assert link.command.velocities == {"waist": 0.3}
    assert events.wait(
        lambda: any(f.readings["waist"].speed_rad_s > 0.1 for f in events.telemetry), DEADLINE_S
    )

    link.emergency_stop("conformance")
    assert sim.wait_until(lambda s: s.all_stopped, DEADLINE_S)
    assert events.safety == ["EMERGENCY STOP (conformance)"]
    stats = link.stats()
    assert stats.sent >= 2
    assert stats.telemetry >= 3
    assert stats.malformed == stats.foreign == 0

    link.set_velocities(shoulder=0.2)
    assert sim.wait_until(lambda s: s.velocities["shoulder"] > 0.0, DEADLINE_S)
    link.shutdown()
    # Zeros go out last, whatever was commanded, and the link says it is closed.
    assert sim.wait_until(lambda s: s.all_stopped, DEADLINE_S)
    assert sim.received_commands()[-1].packet.axes == (0,) * 16
    assert events.states[-1] == LinkState.CLOSED
    if isinstance(link, VirtualLink):
        assert sim.received_commands()[-1].address == VIRTUAL_OCU
