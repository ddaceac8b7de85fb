"""Junk that parses as telemetry (a corrupted or forged datagram) is counted and dropped.

Its tick fits no clock of the robot's: believed, it poisoned the loss figure ("loss 100 %"
for the loss window's 30 s while telemetry flowed at 10 Hz) and held back the real packets
as "late". The receiver is fed real datagrams with their arrival times, as the live link
(and a replay) feed it.
"""

from __future__ import annotations

import pytest

from ocu.link.receiver import Receiver
from ocu.profile import RobotProfile
from ocu.protocol import MotorRecord, TelemetryPacket
from ocu.protocol.wire import make_codec
from ocu.records import LinkEvent, LinkStats, TelemetryFrame

PERIOD_S = 0.1  # 10 Hz telemetry


class Robot:
    """A robot's telemetry at 10 Hz into a receiver, and junk between its packets."""

    def __init__(self, profile: RobotProfile) -> None:
        self.profile = profile
        self.codec = make_codec(profile)
        self.events: list[LinkEvent] = []
        self.receiver = Receiver(profile, self.events.append)
        self.now = 100.0
        self.tick = 5_000_000

    def datagram(self, tick: int) -> bytes:
        return self.codec.encode(TelemetryPacket(tick=tick, motors=(MotorRecord(device_id=4),)))

    def run(self, seconds: float) -> None:
        for _ in range(round(seconds / PERIOD_S)):
            self.now += PERIOD_S
            self.tick += round(PERIOD_S * self.profile.link.telemetry_tick_hz)
            assert self.receiver.received(self.datagram(self.tick), self.now, self.now)

    def junk(self, tick: int) -> bool:
        return self.receiver.received(self.datagram(tick), self.now + 0.01, self.now)

    def stats(self) -> LinkStats:
        return self.receiver.link_stats(
            self.now, sent=0, send_errors=0, rcp_rate_hz=0, send_rate_hz=5, estop_latched=False
        )

    def ticks(self) -> list[int]:
        return [e.packet.tick for e in self.events if isinstance(e, TelemetryFrame)]


@pytest.mark.parametrize(
    "junk_tick",
    [2**64 - 1, 2**40, 5_000_000 + 10_000_000, 3, 0],
    ids=["max", "far ahead", "hours ahead", "far back", "zero"],
)
def test_a_junk_tick_neither_poisons_the_loss_nor_holds_back_telemetry(
    profile: RobotProfile, junk_tick: int
) -> None:
    robot = Robot(profile)
    robot.run(3.0)
    assert robot.stats().loss_estimate == 0.0
    assert not robot.junk(junk_tick)
    robot.run(0.1)
    assert not robot.junk(junk_tick ^ 1)  # even two junk packets in a row that disagree
    robot.run(2.0)
    stats = robot.stats()
    assert stats.loss_estimate == 0.0
    assert stats.malformed == 2
    assert stats.stale_telemetry == 0
    assert junk_tick not in robot.ticks()
    assert len(robot.ticks()) == 51  # every real packet reached the listeners


def test_a_restarted_robot_is_believed_by_its_second_packet_and_the_loss_starts_over(
    profile: RobotProfile,
) -> None:
    robot = Robot(profile)
    robot.run(3.0)
    robot.tick = 0  # the robot rebooted
    robot.now += PERIOD_S
    assert not robot.junk(100)  # the first of the new clock is held ...
    robot.tick = 100
    robot.run(0.1)
    assert robot.ticks()[-1] == 200  # ... and the second confirms it
    robot.run(1.0)
    stats = robot.stats()
    assert stats.loss_estimate == 0.0  # the old clock's ticks are not counted as a gap
    assert stats.malformed == 0
    assert stats.stale_telemetry == 1


def test_a_real_gap_still_counts_as_loss(profile: RobotProfile) -> None:
    robot = Robot(profile)
    robot.run(2.0)
    robot.now += 0.5  # five packets lost on the way
    robot.tick += 500
    robot.run(2.5)
    loss = robot.stats().loss_estimate
    assert loss == pytest.approx(5 / 50)
