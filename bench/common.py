"""What the benchmarks share: percentiles, and one bare robot that stamps the RCPs it reads.

`StampingRobot` plays the robot for latency benchmarks: on any ocu.net transport (a UDP
socket on 127.0.0.1, or the robot end of a VirtualWire) it decodes each datagram, stamps the
first RCP that carries each value of one channel's axis, and can keep its sender's link
connected with an empty telemetry packet now and then. It runs on ocu.net's SelectLoop, the
loop the link and the simulator run on.
"""

from __future__ import annotations

import threading
import time
from typing import TYPE_CHECKING

import numpy as np

from ocu.console.model import ConsoleModel
from ocu.link.base import Link
from ocu.net.loop import SelectLoop
from ocu.net.transport import Address, Transport, UdpTransport
from ocu.profile import RobotProfile
from ocu.protocol import ProtocolError, RemoteControlPacket, TelemetryPacket
from ocu.protocol.wire import make_codec

if TYPE_CHECKING:
    from ocu.qt.link import QtLink
    from ocu.widgets.video import VideoPanel

RECEIVE_BYTES = 65536


def percentile(values: list[float], q: float) -> float:
    """The q-th percentile (0-100) by linear interpolation."""
    return float(np.percentile(values, q))


class StampingRobot:
    """A bare robot that timestamps (perf_counter) the first RCP carrying each axis value.

    `channel` names the axis watched. With `telemetry_period_s`, every sender of RCPs gets an
    empty telemetry packet at most that often, so its link stays CONNECTED.
    """

    def __init__(
        self,
        profile: RobotProfile,
        channel: str,
        *,
        transport: Transport | None = None,
        telemetry_period_s: float | None = None,
    ) -> None:
        self.codec = make_codec(profile)
        self.axis = profile.channels[channel].axis
        self.telemetry_period_s = telemetry_period_s
        self._own_transport = transport is None
        self.transport = transport or UdpTransport(("127.0.0.1", 0))
        self.address: Address = self.transport.address
        self.first_seen: dict[int, float] = {}
        self.foreign = 0
        self._telemetry_due: dict[Address, float] = {}
        self._tick = 0
        self._buffer = bytearray(RECEIVE_BYTES)
        self.cond = threading.Condition()
        self.loop = SelectLoop("bench-robot")
        self.loop.add_reader(self.transport.socket, self._read)
        self.loop.start(lambda now: now + 1.0)  # nothing timed: wake on datagrams only

    def _read(self) -> None:
        while True:
            try:
                got = self.transport.receive(self._buffer)
            except OSError:
                continue  # an ICMP port-unreachable from a link gone
            if got is None:
                return
            arrived = time.perf_counter()
            size, sender = got
            try:
                packet = self.codec.decode(bytes(self._buffer[:size]))
            except ProtocolError:
                self.foreign += 1  # a link probing with extension hellos
                continue
            if isinstance(packet, RemoteControlPacket):
                with self.cond:
                    self.first_seen.setdefault(packet.axes[self.axis], arrived)
                    self.cond.notify_all()
                self._answer(sender, arrived)

    def _answer(self, sender: Address, now: float) -> None:
        if self.telemetry_period_s is None or now < self._telemetry_due.get(sender, 0.0):
            return
        self._telemetry_due[sender] = now + self.telemetry_period_s
        self._tick += 1
        self.transport.send(self.codec.encode(TelemetryPacket(tick=self._tick)), sender)

    def wait_for(self, axis_value: int, timeout_s: float = 2.0) -> float:
        """When the first RCP with this axis value arrived (perf_counter seconds)."""
        with self.cond:
            if not self.cond.wait_for(lambda: axis_value in self.first_seen, timeout_s):
                raise TimeoutError(f"axis value {axis_value} never arrived")
            return self.first_seen[axis_value]

    def forget(self) -> None:
        """Forget every stamp (a new series of values follows)."""
        with self.cond:
            self.first_seen.clear()

    def close(self) -> None:
        """Stop the loop; close the transport if this robot made it."""
        self.loop.stop()
        self.loop.close()
        if self._own_transport:
            self.transport.close()


def video_console(profile: RobotProfile, link: Link) -> tuple[ConsoleModel, QtLink, VideoPanel]:
    """The console's video path over `link`, without the window: model, QtLink, VideoPanel.

    The link is not started; call `qt.start()` (and `qt.shutdown()` at the end).
    """
    from ocu.qt.console import ConsoleBinding
    from ocu.qt.link import QtLink
    from ocu.widgets.video import VideoPanel

    model = ConsoleModel(profile)
    qt = QtLink(link)
    ConsoleBinding(model, qt, qt)
    panel = VideoPanel(model)
    panel.set_link(qt)
    return model, qt, panel
