"""The extended simulator drops an RCP older than the newest it applied (issue 19, item 4).

Datagrams are sent by hand over UDP; the simulator's state says what it applied. Then the
whole chain under the fault that showed the hazard (jitter 200 ms, half the datagrams
duplicated): after a release, no older motion RCP is applied.
"""

from __future__ import annotations

import itertools
import socket
import time
from collections.abc import Iterator

import pytest

from ocu.link.live import UdpLink
from ocu.profile import RobotProfile
from ocu.protocol.extended import SequencedRcp, sequence_newer
from ocu.protocol.mapping import CommandMapper
from ocu.protocol.wire import make_codec, make_extension_codec
from ocu.records import Command
from ocu.sim.faults import FaultConfig
from ocu.sim.simulator import RobotSimulator, SimState

DEADLINE_S = 10.0


@pytest.fixture
def sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    simulator = RobotSimulator(profile, extended=True, telemetry_hz=10.0, video_fps=0.0)
    simulator.start()
    yield simulator
    simulator.stop()


class Client:
    """An OCU by hand: one UDP socket sending RCPs, sequenced or not."""

    def __init__(self, profile: RobotProfile, sim: RobotSimulator) -> None:
        self.sim = sim
        self.mapper = CommandMapper(profile)
        self.codec = make_codec(profile)
        ext = make_extension_codec(profile)
        assert ext is not None
        assert ext.rcp_type is not None
        self.ext = ext
        self.socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)

    def close(self) -> None:
        self.socket.close()

    def sequenced(self, sequence: int, neck: float) -> None:
        packet = self.mapper.to_packet(Command({"neck": neck}))
        self.socket.sendto(self.ext.encode(SequencedRcp(sequence, packet)), self.sim.address)

    def vendor(self, neck: float) -> None:
        packet = self.mapper.to_packet(Command({"neck": neck}))
        self.socket.sendto(self.codec.encode(packet), self.sim.address)

    def wait(self, what: str, predicate: object) -> SimState:
        assert callable(predicate)
        assert self.sim.wait_until(predicate, DEADLINE_S), what
        return self.sim.state()


@pytest.fixture
def client(profile: RobotProfile, sim: RobotSimulator) -> Iterator[Client]:
    ocu = Client(profile, sim)
    yield ocu
    ocu.close()


def test_an_older_sequenced_rcp_is_dropped(client: Client) -> None:
    client.sequenced(10, 0.3)
    state = client.wait("applied #10", lambda s: s.rcp_count == 1)
    assert state.commanded_velocities["neck"] == pytest.approx(0.3, abs=0.01)
    client.sequenced(11, 0.0)
    client.wait("applied #11", lambda s: s.rcp_count == 2)
    client.sequenced(10, 0.3)  # a duplicate of #10, late
    client.sequenced(9, 0.3)  # an older one, late
    state = client.wait("two dropped", lambda s: s.stale_rcp_count == 2)
    assert state.rcp_count == 2
    assert state.commanded_velocities["neck"] == 0.0
    # A vendor RCP sent before the sequenced ones and delivered after them: dropped too.
    client.vendor(0.3)
    state = client.wait("vendor dropped", lambda s: s.stale_rcp_count == 3)
    assert state.commanded_velocities["neck"] == 0.0
    client.sequenced(12, 0.2)
    state = client.wait("applied #12", lambda s: s.rcp_count == 3)
    assert state.commanded_velocities["neck"] == pytest.approx(0.2, abs=0.01)
    assert [r.sequence for r in client.sim.received_commands()] == [10, 11, 12]


def test_the_sequence_wraps(client: Client) -> None:
    client.sequenced(2**32 - 1, 0.3)
    client.sequenced(0, 0.0)
    state = client.wait("both applied", lambda s: s.rcp_count == 2)
    assert state.stale_rcp_count == 0
    assert state.commanded_velocities["neck"] == 0.0


def test_a_new_sequence_starts_after_the_watchdog(client: Client) -> None:
    client.sequenced(1000, 0.3)
    client.wait("applied", lambda s: s.rcp_count == 1)
    # The robot stops on its watchdog; an OCU restarted meanwhile may start anywhere.
    client.wait("watchdog", lambda s: s.watchdog_stopped)
    client.sequenced(5, 0.2)
    state = client.wait("a new sequence", lambda s: s.rcp_count == 2)
    assert state.stale_rcp_count == 0
    # And vendor RCPs are the robot's again once no sequenced one is current.
    client.vendor(0.0)
    client.wait("watchdog again", lambda s: s.watchdog_stopped)
    client.vendor(0.1)
    state = client.wait("vendor applied", lambda s: s.rcp_count == 3)
    assert state.commanded_velocities["neck"] == pytest.approx(0.1, abs=0.01)


def test_a_vendor_robot_gets_vendor_rcps(profile: RobotProfile) -> None:
    with RobotSimulator(profile, telemetry_hz=10.0, video_fps=0.0) as vendor:
        link = UdpLink(profile, vendor.address, extension=True, gui_alive_timeout_s=None)
        link.start()
        try:
            link.set_velocities(neck=0.3)
            assert vendor.wait_until(lambda s: s.velocities["neck"] > 0, DEADLINE_S)
            assert vendor.wait_until(lambda s: s.rcp_count >= 5, DEADLINE_S)
        finally:
            link.shutdown()
        assert all(r.sequence is None for r in vendor.received_commands())
        assert not link.extension_active


def test_after_a_release_no_older_motion_is_applied_under_jitter_and_duplicates(
    profile: RobotProfile,
) -> None:
    faults = FaultConfig(jitter_ms=200.0, duplicate=0.5)
    with RobotSimulator(
        profile, extended=True, telemetry_hz=10.0, video_fps=0.0, faults=faults, seed=7
    ) as sim:
        link = UdpLink(profile, sim.address, extension=True, gui_alive_timeout_s=None)
        link.start()
        try:
            deadline = time.monotonic() + DEADLINE_S
            while not link.extension_active:
                assert time.monotonic() < deadline, "the extension was never detected"
                time.sleep(0.01)
            # The vendor RCPs sent before the extension was seen arrive within the jitter's
            # bound by the simulator's own clock (a loaded simulator delivers late, but in
            # order of its clock): past it, only sequenced RCPs can arrive.
            detected = time.monotonic()
            assert sim.wait_until(lambda s: s.time_s > detected + 0.5, DEADLINE_S)
            for step in range(10):  # a slider moved about, then released
                link.set_velocities(neck=0.1 + 0.02 * step)
                time.sleep(0.02)  # the operator's pace, not a synchronisation
            link.set_velocities(neck=0.0)
            released = time.monotonic()
            # Every copy sent before the release has arrived 0.2 s (the jitter's bound) later.
            assert sim.wait_until(lambda s: s.time_s > released + 0.5, DEADLINE_S)
        finally:
            link.shutdown()
        received = sim.received_commands()
        assert all(r.sequence is not None for r in received if r.time_s > released)
        sequences = [r.sequence for r in received if r.sequence is not None]
        assert all(sequence_newer(b, a) for a, b in itertools.pairwise(sequences))
        zero = next(r for r in received if r.time_s >= released and not any(r.packet.axes))
        late_motion = [r for r in received if r.time_s > zero.time_s and any(r.packet.axes)]
        assert not late_motion, late_motion
        assert sim.state().stale_rcp_count > 0  # there were older copies, and they were dropped
