"""The codecs of one robot: the profile's frame type IDs, built in one place."""

from __future__ import annotations

from ocu.profile import RobotProfile
from ocu.protocol.codec import Codec
from ocu.protocol.extended import ExtendedCodec


def make_codec(profile: RobotProfile) -> Codec:
    """The vendor codec with the profile's frame type IDs."""
    types = profile.link.frame_types
    return Codec(rcp_type=types.rcp, telemetry_type=types.telemetry, video_type=types.video)


def make_extension_codec(profile: RobotProfile) -> ExtendedCodec | None:
    """The protocol extension's codec with the profile's IDs, None if it defines none."""
    extension = profile.extension
    if extension is None:
        return None
    types = extension.frame_types
    return ExtendedCodec(types.hello, types.video_fragment, types.status, types.scan, types.rcp)
