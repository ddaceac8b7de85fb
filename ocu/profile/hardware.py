"""What the wire needs of a robot (hardware settings): packet IDs, link timing, the
protocol extension, video transport, and the velocity channels the RCP carries."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class FrameTypes:
    """Wire IDs of the vendor packet types."""

    rcp: int
    telemetry: int
    video: int


@dataclass(frozen=True)
class LinkSettings:
    """Network and timing facts of the link."""

    address: str
    port: int
    send_rate_hz: float
    send_rate_min_hz: float
    send_rate_max_hz: float
    robot_watchdog_s: float
    telemetry_rate_hz: float
    telemetry_tick_hz: float
    link_lost_after_s: float
    gui_alive_timeout_s: float
    estop_repeats: int
    estop_window_s: float
    default_video_bitrate: float
    camera_names: tuple[str, ...]
    frame_types: FrameTypes


@dataclass(frozen=True)
class ExtensionFrameTypes:
    """Wire IDs of our protocol extension's packet types (not vendor facts)."""

    hello: int
    video_fragment: int
    status: int
    # The planar range scan (robot -> OCU); None: this extension has no range sensor.
    scan: int | None = None
    # The sequenced RCP (OCU -> robot); None: the OCU sends vendor RCPs to any robot.
    rcp: int | None = None


@dataclass(frozen=True)
class ExtensionSettings:
    """The open protocol extension: its IDs and what the OCU asks of an extended robot."""

    probe: bool
    frame_types: ExtensionFrameTypes
    max_datagram_bytes: int
    stream_width_px: int
    stream_height_px: int
    stream_fps: int
    # Ask for datagrams as large as the route's MTU carries unfragmented (65507 bytes on the
    # loopback, 1472 on a 1500-byte link); max_datagram_bytes where the MTU is unknown.
    fit_datagrams_to_path: bool = True


@dataclass(frozen=True)
class VideoSettings:
    """OCU-side video settings: no-signal time, battery warning, reassembly bounds."""

    no_signal_after_s: float = 1.0
    battery_warning_percent: float = 20.0
    reassembly_max_frames: int = 16
    reassembly_max_bytes: int = 8 * 1024 * 1024
    reassembly_timeout_s: float = 0.5
    # Decode each JPEG at the size its cell shows it (libjpeg DCT scaling, 1/2 to 1/8).
    decode_at_display_size: bool = True
    # OpenCV's worker threads for decoding and correction; 0: OpenCV's own choice.
    opencv_threads: int = 1


@dataclass(frozen=True)
class Channel:
    """One velocity channel: which RCP axis carries it, how SI maps to axis units, its role.

    `directions` are the words for + and − ("up", "down"); `switch` gives the channel a
    three-way switch in the console; `locked_while_driving` says the robot refuses to move it
    while the chassis moves (the Engineer's waist). `axis_sign` is -1 when the robot moves the
    channel the negative way for a positive axis value (the OCU then sends the axis negated).
    `axis_per_unit` is the channel's own scale when the profile gives one, else the SI
    constant its `scale` names.
    """

    name: str
    axis: int
    axis_per_unit: float
    unit: str
    min_speed: float
    default_max: float
    hard_max: float
    role: str | None = None
    switch: bool = False
    directions: tuple[str, str] = ("+", "-")
    locked_while_driving: bool = False
    axis_sign: int = 1
