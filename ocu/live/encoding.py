"""The live server's channels and their encoding, in the relay process (ocu.live.relay).

The link's items (ocu.record.convert: what the recorder takes) become the recorder's ROS 2
messages, the same CDR bytes a recording holds, plus the robot's /tf, /tf_static,
/robot_description, /scan and /diagnostics (ocu.live.robot). The console's own messages
(the navigator's /odom and /map, the scene) come as message dicts and are encoded here too.
A message is encoded only when some client subscribed to its channel, or when its channel
keeps its last message for a late subscriber.

This is the costly Python of serving (the CDR encoder, the URDF tree's transforms at the
telemetry rate): here it shares no interpreter with the operator's key path.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any, Final

from ocu.link.diagnostics import link_report
from ocu.live import navigation as nv
from ocu.live import robot as rb
from ocu.live import scene as sc
from ocu.live import wire
from ocu.live.messages import ARM_TWIST, TWIST_STAMPED
from ocu.profile import RobotProfile
from ocu.record import schemas as s
from ocu.record.convert import (
    DECODED_TOPICS,
    EVENT,
    STATS,
    TELEMETRY,
    Item,
    MessageConverter,
    topic_type,
)
from ocu.records import LinkState, ScanFrame, TelemetryFrame

log = logging.getLogger("ocu.live")

SCAN: Final = -1  # the queue kind of a range scan (the recorder keeps only its datagram)


@dataclass
class Channel:
    info: wire.ChannelInfo
    encoder: s.Encoder
    latched: tuple[int, bytes] | None = None
    keeps_last: bool = False


#: (channel, log time in ns, payload): one encoded message for the channel's subscribers.
FanOut = Callable[[Channel, int, bytes], None]


class Encoding:
    """Every channel of one robot, and its messages encoded for `fan_out`.

    `wall_ns` maps the console's monotonic times to wall-clock nanoseconds (the recorder's
    mapping, made once in the console); `subscribed(channel id)` says whether anyone
    listens; `advertise` is told of a channel made after the start.
    """

    def __init__(
        self,
        profile: RobotProfile,
        frames: rb.RobotFrames | None,
        wall_ns: Callable[[float], int],
        now: float,
        *,
        fan_out: FanOut,
        subscribed: Callable[[int], bool],
        advertise: Callable[[wire.ChannelInfo], None],
    ) -> None:
        self.profile = profile
        self.frames = frames
        self.wall_ns = wall_ns
        self.fan_out = fan_out
        self.subscribed = subscribed
        self.advertise = advertise
        self.channels: dict[str, Channel] = {}
        self.by_id: dict[int, Channel] = {}
        self._link_state = LinkState.CONNECTING
        self._converter = MessageConverter(profile, wall_ns, self.publish)
        self._declare(now)

    def _declare(self, now: float) -> None:
        for topic in s.RAW_TOPICS:
            self._channel(topic, s.RAW_PACKET)
        for topic, message_type in DECODED_TOPICS:
            self._channel(topic, message_type)
        for name in self.profile.link.camera_names:
            self._channel(s.camera_topic(name), s.COMPRESSED_IMAGE)
        self._channel(rb.SCAN, rb.LASER_SCAN)
        self._channel(rb.DIAGNOSTICS, rb.DIAGNOSTIC_ARRAY)
        if self.profile.drive_channels is not None:  # a chassis: odometry and a map
            self._channel(nv.ODOM, nv.ODOMETRY)
            self._channel(nv.MAP, nv.OCCUPANCY_GRID)
            self._channel(nv.PLAN, nv.PATH)
            footprint = self.profile.navigation.footprint
            if footprint is not None:
                outline = self._channel(nv.FOOTPRINT, nv.POLYGON_STAMPED, keeps_last=True)
                log_ns = self.wall_ns(now)
                message = nv.footprint_message(footprint.corners_m, s.stamp(log_ns))
                outline.latched = (log_ns, outline.encoder(message))
        for topic in sc.topics_of(self.profile):
            self._channel(topic, sc.SCENE_UPDATE, keeps_last=True)
        if self.profile.arm is not None:
            # The arm twists the live source took. Advertised for its definition too: a
            # client learns TwistStamped only from a channel of the server's (Foxglove's
            # Publish panel then publishes /arm/twist_cmd in cdr).
            self._channel(ARM_TWIST, TWIST_STAMPED)
        self._channel(rb.TF, rb.TF_MESSAGE)
        frames = self.frames
        if frames is not None:
            static = self._channel(rb.TF_STATIC, rb.TF_MESSAGE, keeps_last=True)
            description = self._channel(rb.ROBOT_DESCRIPTION, rb.STRING, keeps_last=True)
            log_ns = self.wall_ns(now)
            static.latched = (log_ns, static.encoder(frames.static_message(s.stamp(log_ns))))
            description.latched = (log_ns, description.encoder(frames.description_message()))

    def _channel(
        self, topic: str, message_type: s.MessageType, *, keeps_last: bool = False
    ) -> Channel:
        channel_id = len(self.by_id) + 1
        info = wire.ChannelInfo(channel_id, topic, message_type.name, message_type.definition)
        channel = Channel(info, s.make_encoder(message_type), keeps_last=keeps_last)
        self.channels[topic] = channel
        self.by_id[channel_id] = channel
        return channel

    def serve(self, items: Iterable[Item], dropped: int) -> None:
        """The link's items, in order (`dropped`: items the console's queue lost so far)."""
        for item in items:
            try:
                self._serve_item(item, dropped)
            except Exception:
                # One item the conversion cannot take must not end the serving of the rest.
                log.exception("live: cannot serve a %s item", item[0])

    def _serve_item(self, item: Item, dropped: int) -> None:
        kind, mono = item[0], item[1]
        if kind == SCAN:
            scan: ScanFrame = item[2]
            self.publish(mono, rb.SCAN, rb.scan_message(scan, s.stamp(self.wall_ns(mono))))
            return
        self._converter.convert(item, dropped)
        if kind == TELEMETRY and self.frames is not None:
            self._publish_tf(mono, item[2])
        elif kind == EVENT and item[2] == s.EVENT_LINK_STATE:
            self._link_state = LinkState(item[3])
        elif kind == STATS:
            report = link_report(self._link_state, item[2], self.profile.name)
            message = rb.diagnostics_message(report, s.stamp(self.wall_ns(mono)))
            self.publish(mono, rb.DIAGNOSTICS, message)

    def _publish_tf(self, mono: float, frame: TelemetryFrame) -> None:
        channel = self.channels[rb.TF]
        if not self.subscribed(channel.info.id):
            return
        assert self.frames is not None
        positions = {
            name: reading.angle_rad
            for name, reading in frame.readings.items()
            if reading.angle_rad is not None
        }
        self.publish(
            mono, rb.TF, self.frames.moving_message(positions, s.stamp(self.wall_ns(mono)))
        )

    def publish(
        self, mono: float, topic: str, message: dict[str, Any], publish_ns: int | None = None
    ) -> None:
        """One message on `topic` (a channel is made for a topic not declared yet)."""
        channel = self.channels.get(topic)
        if channel is None:
            channel = self._channel(topic, topic_type(topic))
            self.advertise(channel.info)
        if not channel.keeps_last and not self.subscribed(channel.info.id):
            return
        self.encoded(channel, self.wall_ns(mono), channel.encoder(message))

    def encoded(self, channel: Channel, log_ns: int, payload: bytes) -> None:
        """One message encoded already (the console's /map)."""
        if channel.keeps_last:
            channel.latched = (log_ns, payload)
        self.fan_out(channel, log_ns, payload)
