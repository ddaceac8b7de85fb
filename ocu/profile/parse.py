"""Reading and validating a profile's TOML document into a RobotProfile, section by section
(each table through reader.py's TableReader); errors name the file and the key."""

from __future__ import annotations

import datetime as dt
import itertools
import math
import tomllib
from importlib import resources
from pathlib import Path
from typing import Any

from ocu.profile.description import (
    ArmSettings,
    AssistSettings,
    CameraCalibration,
    CameraMount,
    CameraSettings,
    Footprint,
    Measurement,
    Motor,
    NavigationSettings,
    OdometrySettings,
    RobotProfile,
    ZoneSettings,
)
from ocu.profile.hardware import (
    Channel,
    ExtensionFrameTypes,
    ExtensionSettings,
    FrameTypes,
    LinkSettings,
    VideoSettings,
)
from ocu.profile.keys import (
    ARM_KEYS,
    ASSIST_KEYS,
    AXIS_COUNT,
    AXIS_MAX,
    BUTTON_COUNT,
    BUTTON_KEYS,
    CAMERA_KEYS,
    CAMERA_MODELS,
    CHANNEL_KEYS,
    CHANNEL_ROLES,
    CHASSIS_KEYS,
    COLOUR_MODES,
    DISTORTION_LENGTHS,
    EXTENSION_FRAME_TYPE_KEYS,
    EXTENSION_KEYS,
    FRAME_TYPE_KEYS,
    LINK_KEYS,
    LINK_LOST_MAX_S,
    MEASUREMENT_KEYS,
    MOTOR_KEYS,
    MOTOR_POSITION_KEYS,
    NAVIGATION_KEYS,
    ODOMETRY_KEYS,
    OPTIONAL_EXTENSION_FRAME_TYPE_KEYS,
    SCALE_NAMES,
    SI_KEYS,
    TOOL_AXES,
    TOP_KEYS,
    VIDEO_KEYS,
    ZONE_KEYS,
    ProfileError,
    did_you_mean,
)
from ocu.profile.reader import TableReader


def default_profile_path() -> Path:
    """Path of the Engineer profile shipped with the package."""
    return Path(str(resources.files("ocu") / "profiles" / "engineer.toml"))


def load_profile(path: str | Path | None = None) -> RobotProfile:
    """Read and validate a profile; the shipped Engineer profile when path is None."""
    profile_path = Path(path) if path is not None else default_profile_path()
    return parse_profile(load_profile_data(profile_path), source=str(profile_path))


def load_profile_data(path: str | Path | None = None) -> dict[str, Any]:
    """A profile file's TOML document, not yet validated (the shipped one when path is None).

    For tools that write a profile from another one (ocu calibrate, ocu-sim --scramble).
    """
    profile_path = Path(path) if path is not None else default_profile_path()
    try:
        text = profile_path.read_text(encoding="utf-8")
    except OSError as err:
        raise ProfileError(f"cannot read profile {profile_path}: {err.strerror}") from err
    except UnicodeDecodeError as err:
        raise ProfileError(f"{profile_path}: not UTF-8 text: {err}") from err
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ProfileError(f"{profile_path}: not valid TOML: {err}") from err


def _parse_channel(name: str, reader: TableReader, scales: dict[str, float]) -> Channel:
    axis = reader.integer("axis", low=0, high=AXIS_COUNT - 1)
    scale = reader.string("scale")
    if scale not in scales:
        raise ProfileError(f"{reader.where}.scale: must be one of {SCALE_NAMES}, got {scale!r}")
    per_unit = scales[scale]
    if reader.optional("axis_per_unit"):
        per_unit = reader.number("axis_per_unit", low=1e-9)
    axis_sign = 1
    if reader.optional("axis_sign"):
        axis_sign = reader.integer("axis_sign", low=-1, high=1)
        if axis_sign == 0:
            raise ProfileError(f"{reader.where}.axis_sign: must be 1 or -1, got 0")
    min_speed = reader.number("min_speed", low=0.0)
    hard_max = reader.number("hard_max", low=0.0)
    default_max = reader.number("default_max", low=0.0, high=hard_max)
    if min_speed > default_max:
        raise ProfileError(f"{reader.where}.min_speed: above default_max ({default_max})")
    if hard_max * per_unit > AXIS_MAX:
        limit = AXIS_MAX / per_unit
        raise ProfileError(
            f"{reader.where}.hard_max: {hard_max} needs axis value {hard_max * per_unit:.0f}, "
            f"over the int16 range; at most {limit:.4f}"
        )
    role = reader.choice("role", CHANNEL_ROLES) if reader.optional("role") else None
    directions: tuple[str, str] = ("+", "-")
    if reader.optional("directions"):
        words = reader.table["directions"]
        if (
            not isinstance(words, list)
            or len(words) != 2
            or not all(isinstance(w, str) and w.strip() for w in words)
        ):
            raise ProfileError(
                f'{reader.where}.directions: two words for + and -, e.g. ["up", "down"]'
            )
        directions = (words[0].strip(), words[1].strip())
    return Channel(
        name=name,
        axis=axis,
        axis_per_unit=per_unit,
        unit=reader.string("unit"),
        min_speed=min_speed,
        default_max=default_max,
        hard_max=hard_max,
        role=role,
        switch=reader.boolean("switch") if reader.optional("switch") else False,
        directions=directions,
        locked_while_driving=(
            reader.boolean("locked_while_driving")
            if reader.optional("locked_while_driving")
            else False
        ),
        axis_sign=axis_sign,
    )


def _parse_motor(name: str, reader: TableReader, channels: dict[str, Channel]) -> Motor:
    device_id = reader.integer("device_id", low=0, high=255)
    channel = reader.string("channel") if reader.optional("channel") else None
    if channel is not None and channel not in channels:
        hint = did_you_mean(channel, channels)
        raise ProfileError(f"{reader.where}.channel: unknown channel {channel!r}; {hint}")
    track = reader.string("track") if reader.optional("track") else None
    if track is not None and track not in ("left", "right"):
        raise ProfileError(f"{reader.where}.track: must be 'left' or 'right'")
    ticks_per_rad: float | None = None
    zero_offset = 0
    limits: tuple[float, float] | None = None
    limits_deg: tuple[float, float] | None = None
    if reader.optional("ticks_per_rad"):
        ticks_per_rad = reader.number("ticks_per_rad", low=1e-9)
        zero_offset = reader.integer("zero_offset_ticks", low=0, high=2**32 - 1)
        raw_limits = reader.table.get("limits_deg")
        if (
            not isinstance(raw_limits, list)
            or len(raw_limits) != 2
            or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                for v in raw_limits
            )
            or not raw_limits[0] < raw_limits[1]
        ):
            raise ProfileError(
                f"{reader.where}.limits_deg: two finite numbers; "
                "must be [low, high] with low < high"
            )
        limits_deg = (float(raw_limits[0]), float(raw_limits[1]))
        limits = (math.radians(limits_deg[0]), math.radians(limits_deg[1]))
    else:
        for key in MOTOR_POSITION_KEYS:
            if reader.optional(key):
                raise ProfileError(
                    f"{reader.where}.{key}: needs ticks_per_rad (without it the motor "
                    "reports no position)"
                )
    return Motor(
        name=name,
        device_id=device_id,
        channel=channel,
        track=track,
        ticks_per_rad=ticks_per_rad,
        zero_offset_ticks=zero_offset,
        limits_rad=limits,
        limits_deg=limits_deg,
    )


def _parse_extension(reader: TableReader, vendor: FrameTypes) -> ExtensionSettings:
    types_reader = reader.sub(
        "frame_types", (*EXTENSION_FRAME_TYPE_KEYS, *OPTIONAL_EXTENSION_FRAME_TYPE_KEYS)
    )
    types = ExtensionFrameTypes(
        hello=types_reader.integer("hello", low=0, high=255),
        video_fragment=types_reader.integer("video_fragment", low=0, high=255),
        status=types_reader.integer("status", low=0, high=255),
        scan=(
            types_reader.integer("scan", low=0, high=255) if types_reader.optional("scan") else None
        ),
        rcp=types_reader.integer("rcp", low=0, high=255) if types_reader.optional("rcp") else None,
    )
    ids = [types.hello, types.video_fragment, types.status, vendor.rcp, vendor.telemetry]
    ids.append(vendor.video)
    ids.extend(extra for extra in (types.scan, types.rcp) if extra is not None)
    if len(set(ids)) != len(ids):
        raise ProfileError(
            f"{types_reader.where}: the IDs must differ from each other and from link.frame_types"
        )
    return ExtensionSettings(
        probe=reader.boolean("probe"),
        frame_types=types,
        # 64 bytes leave room for the fragment header; 65507 is the UDP/IPv4 payload limit.
        max_datagram_bytes=reader.integer("max_datagram_bytes", low=64, high=65507),
        stream_width_px=reader.integer("stream_width_px", low=16, high=4096),
        stream_height_px=reader.integer("stream_height_px", low=16, high=4096),
        stream_fps=reader.integer("stream_fps", low=0, high=255),
        fit_datagrams_to_path=(
            reader.boolean("fit_datagrams_to_path")
            if reader.optional("fit_datagrams_to_path")
            else ExtensionSettings.fit_datagrams_to_path
        ),
    )


def _parse_video(reader: TableReader) -> VideoSettings:
    return VideoSettings(
        no_signal_after_s=reader.number("no_signal_after_s", low=0.01),
        battery_warning_percent=reader.number("battery_warning_percent", low=0.0, high=100.0),
        reassembly_max_frames=reader.integer("reassembly_max_frames", low=1, high=1024),
        reassembly_max_bytes=reader.integer("reassembly_max_bytes", low=65536, high=2**30),
        reassembly_timeout_s=reader.number("reassembly_timeout_s", low=0.001),
        decode_at_display_size=(
            reader.boolean("decode_at_display_size")
            if reader.optional("decode_at_display_size")
            else VideoSettings.decode_at_display_size
        ),
        opencv_threads=(
            reader.integer("opencv_threads", low=0, high=64)
            if reader.optional("opencv_threads")
            else VideoSettings.opencv_threads
        ),
    )


def _parse_camera(name: str, index: int, reader: TableReader) -> CameraSettings:
    model = reader.choice("model", CAMERA_MODELS)
    size = reader.numbers("calibration_size_px", (2,), low=1.0)
    if not all(v.is_integer() for v in size):
        raise ProfileError(f"{reader.where}.calibration_size_px: must be whole pixels")
    focal = reader.numbers("focal_px", (2,), low=1e-6)
    centre = reader.numbers("centre_px", (2,))
    if not (0.0 <= centre[0] <= size[0] and 0.0 <= centre[1] <= size[1]):
        raise ProfileError(f"{reader.where}.centre_px: must lie inside calibration_size_px")
    distortion = reader.numbers("distortion", DISTORTION_LENGTHS[model])
    gains = reader.numbers("fixed_gains_rgb", (3,), low=0.0)
    calibration = CameraCalibration(
        model=model,
        size_px=(int(size[0]), int(size[1])),
        focal_px=(focal[0], focal[1]),
        centre_px=(centre[0], centre[1]),
        distortion=distortion,
        balance=reader.number("balance", low=0.0, high=1.0),
    )
    return CameraSettings(
        name=name,
        index=index,
        calibration=calibration,
        undistort=reader.boolean("undistort"),
        colour=reader.choice("colour", COLOUR_MODES),
        fixed_gains_rgb=(gains[0], gains[1], gains[2]),
        mount=_parse_mount(reader),
    )


def _parse_mount(reader: TableReader) -> CameraMount | None:
    if not reader.optional("mount_xyz_m"):
        for key in ("mount_yaw_deg", "mount_pitch_deg", "mount_link"):
            if reader.optional(key):
                raise ProfileError(f"{reader.where}.{key}: needs mount_xyz_m")
        return None
    xyz = reader.numbers("mount_xyz_m", (3,))
    yaw = reader.number("mount_yaw_deg", low=-180.0, high=180.0)
    pitch = (
        reader.number("mount_pitch_deg", low=-89.0, high=89.0)
        if reader.optional("mount_pitch_deg")
        else 0.0
    )
    link = reader.string("mount_link") if reader.optional("mount_link") else None
    return CameraMount((xyz[0], xyz[1], xyz[2]), math.radians(yaw), math.radians(pitch), link)


def _ascending(reader: TableReader, key: str, count: int | None, low: float) -> tuple[float, ...]:
    value = reader.table.get(key)
    lengths = (count,) if count is not None else tuple(range(1, 9))
    numbers = reader.numbers(key, lengths, low=low)
    if count is None and any(b <= a for a, b in itertools.pairwise(numbers)):
        raise ProfileError(f"{reader.where}.{key}: must grow from zone to zone, got {value!r}")
    return numbers


def _parse_navigation(reader: TableReader) -> NavigationSettings:
    default = NavigationSettings()
    footprint = Footprint(
        front_m=reader.number("footprint_front_m", low=0.01),
        rear_m=reader.number("footprint_rear_m", low=0.01),
        half_width_m=reader.number("footprint_half_width_m", low=0.01),
    )
    mount = reader.numbers("scan_mount_xy_m", (2,)) if reader.optional("scan_mount_xy_m") else None
    odometry = default.odometry
    if reader.optional("odometry"):
        o = reader.sub("odometry", ODOMETRY_KEYS)
        odometry = OdometrySettings(
            stale_after_s=o.number("stale_after_s", low=0.05),
            linear_noise_m2_per_m=o.number("linear_noise_m2_per_m", low=0.0),
            heading_noise_rad2_per_rad=o.number("heading_noise_rad2_per_rad", low=0.0),
            heading_drift_rad2_per_m=o.number("heading_drift_rad2_per_m", low=0.0),
            commanded_noise_factor=o.number("commanded_noise_factor", low=1.0),
            imu_heading_sigma_rad=math.radians(o.number("imu_heading_sigma_deg", low=0.0)),
        )
    zones = default.zones
    if reader.optional("zones"):
        z = reader.sub("zones", ZONE_KEYS)
        within = _ascending(z, "within_m", None, 0.0)
        stop = z.number("stop_m", low=0.0)
        if within[0] <= stop:
            raise ProfileError(f"{z.where}.within_m: the first zone must lie beyond stop_m")
        zones = ZoneSettings(
            stop_m=stop,
            within_m=within,
            max_linear_m_s=_ascending(z, "max_linear_m_s", len(within), 1e-6),
            max_angular_rad_s=_ascending(z, "max_angular_rad_s", len(within), 1e-6),
        )
    assist = default.assist
    if reader.optional("assist"):
        a = reader.sub("assist", ASSIST_KEYS)
        assist = AssistSettings(
            linear_gain_m_per_s2=a.number("linear_gain_m_per_s2", low=1e-6),
            samson_b=a.number("samson_b", low=0.0),
            samson_xi=a.number("samson_xi", low=0.01, high=1.0),
            cruise_m_s=a.number("cruise_m_s", low=0.01),
            goal_tolerance_m=a.number("goal_tolerance_m", low=0.001),
            max_lag_m=a.number("max_lag_m", low=0.01),
        )
    return NavigationSettings(
        footprint=footprint,
        scan_mount_xy_m=(mount[0], mount[1]) if mount is not None else default.scan_mount_xy_m,
        scan_stale_after_s=(
            reader.number("scan_stale_after_s", low=0.01)
            if reader.optional("scan_stale_after_s")
            else default.scan_stale_after_s
        ),
        odometry=odometry,
        zones=zones,
        assist=assist,
    )


def _parse_cameras(root: TableReader, names: tuple[str, ...]) -> tuple[CameraSettings, ...]:
    # A camera without a table has no calibration and no correction by default.
    tables = (
        root.sub("cameras", names, unknown="not in link.camera_names")
        if root.optional("cameras")
        else TableReader({}, "profile.cameras", None)
    )
    return tuple(
        _parse_camera(name, index, tables.sub(name, CAMERA_KEYS))
        if tables.optional(name)
        else CameraSettings(name=name, index=index)
        for index, name in enumerate(names)
    )


def _parse_arm(reader: TableReader, motors: dict[str, Motor]) -> ArmSettings:
    joints = reader.table.get("joints")
    if not isinstance(joints, list) or not joints or not all(isinstance(j, str) for j in joints):
        raise ProfileError(f"{reader.where}.joints: must be a non-empty list of motor names")
    for name in joints:
        motor = motors.get(name)
        if motor is None:
            raise ProfileError(
                f"{reader.where}.joints: unknown motor {name!r}; {did_you_mean(name, motors)}"
            )
        if not motor.has_position or motor.channel is None:
            raise ProfileError(
                f"{reader.where}.joints: {name!r} must report a position and have a channel"
            )
    if len(set(joints)) != len(joints):
        raise ProfileError(f"{reader.where}.joints: a joint is named twice")
    linear = reader.number("linear_speed_m_s", low=1e-6)
    pitch = reader.number("pitch_speed_deg_s", low=1e-6)
    slow = reader.number("singularity_slow", low=1.0)
    poses: dict[str, dict[str, float]] = {}
    if reader.optional("poses"):
        table = reader.sub("poses", None)
        for name in table.table:
            pose = table.sub(name, joints, unknown="not one of arm.joints")
            angles = {}
            for joint in pose.table:
                degrees = pose.number(joint)
                low, high = motors[joint].limits_deg or (-math.inf, math.inf)
                if not low <= degrees <= high:
                    raise ProfileError(
                        f"{pose.where}.{joint}: {degrees}° outside the limits [{low}, {high}]"
                    )
                angles[joint] = math.radians(degrees)
            if set(angles) != set(joints):
                missing = ", ".join(j for j in joints if j not in angles)
                raise ProfileError(f"{pose.where}: every arm joint needs an angle ({missing})")
            poses[name] = angles
    return ArmSettings(
        base_link=reader.string("base_link"),
        tool_link=reader.string("tool_link"),
        camera_link=reader.string("camera_link") if reader.optional("camera_link") else None,
        joints=tuple(joints),
        linear_speed_m_s=linear,
        max_linear_speed_m_s=reader.number("max_linear_speed_m_s", low=linear),
        pitch_speed_rad_s=math.radians(pitch),
        max_pitch_speed_rad_s=math.radians(reader.number("max_pitch_speed_deg_s", low=pitch)),
        acceleration_rad_s2=math.radians(reader.number("acceleration_deg_s2", low=1e-3)),
        joint_limit_margin_rad=math.radians(
            reader.number("joint_limit_margin_deg", low=0.0, high=45.0)
        ),
        singularity_slow=slow,
        singularity_stop=reader.number("singularity_stop", low=slow),
        clearance_m=reader.number("clearance_m", low=0.0),
        slow_distance_m=reader.number("slow_distance_m", low=0.0),
        ground_z_m=reader.number("ground_z_m") if reader.optional("ground_z_m") else None,
        twist_timeout_s=reader.number("twist_timeout_s", low=0.01, high=2.0),
        poses=poses,
        tool_axis=reader.choice("tool_axis", TOOL_AXES) if reader.optional("tool_axis") else "x",
    )


def _link_lost_after_s(link: TableReader) -> float:
    """LINK LOST's delay: longer than one telemetry period (or it would come between any two
    packets), at most LINK_LOST_MAX_S (or it would never come when it matters)."""
    period_s = 1.0 / link.number("telemetry_rate_hz", low=0.01)
    value = link.number("link_lost_after_s", low=0.01)
    if value > LINK_LOST_MAX_S:
        raise ProfileError(
            f"{link.where}.link_lost_after_s: must be <= {LINK_LOST_MAX_S:g} s, got {value:g}: "
            "the operator must learn within seconds that the robot is no longer heard"
        )
    if value <= period_s:
        raise ProfileError(
            f"{link.where}.link_lost_after_s: must be longer than one telemetry period "
            f"({period_s:g} s at telemetry_rate_hz), got {value:g}: LINK LOST would come "
            "between any two packets"
        )
    return value


def parse_profile(data: dict[str, Any], source: str = "<profile>") -> RobotProfile:
    """Validate a decoded TOML document and build the profile.

    Every ProfileError names the file (`source`) and the key: "FILE: profile.link.port: ...".
    """
    try:
        return _parse_profile(data, source)
    except ProfileError as err:
        raise ProfileError(f"{source}: {err}") from err


def _parse_profile(data: dict[str, Any], source: str) -> RobotProfile:
    root = TableReader(data, "profile", TOP_KEYS)
    link = root.sub("link", LINK_KEYS)
    frame_reader = link.sub("frame_types", FRAME_TYPE_KEYS)
    frame_types = FrameTypes(
        rcp=frame_reader.integer("rcp", low=0, high=255),
        telemetry=frame_reader.integer("telemetry", low=0, high=255),
        video=frame_reader.integer("video", low=0, high=255),
    )
    if len({frame_types.rcp, frame_types.telemetry, frame_types.video}) != 3:
        raise ProfileError("profile.link.frame_types: the three IDs must differ")
    rate_min = link.number("send_rate_min_hz", low=0.1)
    rate_max = link.number("send_rate_max_hz", low=rate_min)
    cameras = link.table.get("camera_names")
    if not isinstance(cameras, list) or not cameras or not all(isinstance(c, str) for c in cameras):
        raise ProfileError("profile.link.camera_names: must be a non-empty list of names")
    if len(set(cameras)) != len(cameras) or len(cameras) > 255:
        raise ProfileError("profile.link.camera_names: names must be distinct, at most 255")
    link_settings = LinkSettings(
        address=link.string("address"),
        port=link.integer("port", low=1, high=65535),
        send_rate_hz=link.number("send_rate_hz", low=rate_min, high=rate_max),
        send_rate_min_hz=rate_min,
        send_rate_max_hz=rate_max,
        robot_watchdog_s=link.number("robot_watchdog_s", low=0.01),
        telemetry_rate_hz=link.number("telemetry_rate_hz", low=0.01),
        telemetry_tick_hz=link.number("telemetry_tick_hz", low=1.0),
        link_lost_after_s=_link_lost_after_s(link),
        gui_alive_timeout_s=link.number("gui_alive_timeout_s", low=0.01),
        estop_repeats=link.integer("estop_repeats", low=1, high=100),
        estop_window_s=link.number("estop_window_s", low=0.0, high=1.0),
        default_video_bitrate=link.number("default_video_bitrate", low=0.0),
        camera_names=tuple(cameras),
        frame_types=frame_types,
    )

    si = root.sub("si", SI_KEYS)
    scales = {
        "linear": si.number("linear_axis_per_m_s", low=1e-9),
        "rotation": si.number("rotation_axis_per_rad_s", low=1e-9),
        "joint": si.number("joint_axis_per_rad_s", low=1e-9),
    }
    # Channels are named by the profile; what they do is their role.
    channels_reader = root.sub("channels", None)
    channels: dict[str, Channel] = {}
    for name in channels_reader.table:
        channels[name] = _parse_channel(name, channels_reader.sub(name, CHANNEL_KEYS), scales)
    if not channels:
        raise ProfileError("profile.channels: at least one channel is needed")
    axes = [c.axis for c in channels.values()]
    if len(set(axes)) != len(axes):
        raise ProfileError("profile.channels: two channels share one axis")
    for role in CHANNEL_ROLES:
        having = [c.name for c in channels.values() if c.role == role]
        if len(having) > 1:
            raise ProfileError(f"profile.channels: {having} all have role {role!r}; one may")
    roles = {c.role for c in channels.values() if c.role is not None}
    if roles and roles != set(CHANNEL_ROLES):
        raise ProfileError(
            f"profile.channels: the chassis needs both roles {list(CHANNEL_ROLES)}, "
            f"found only {sorted(roles)}"
        )

    # Motors are named by the profile: any name, each a table of known keys.
    motors_reader = root.sub("motors", None)
    motors: dict[str, Motor] = {}
    for name in motors_reader.table:
        motors[name] = _parse_motor(name, motors_reader.sub(name, MOTOR_KEYS), channels)
    ids = [m.device_id for m in motors.values()]
    if len(set(ids)) != len(ids):
        raise ProfileError("profile.motors: two motors share one device_id")
    if len(motors) > 10:
        raise ProfileError("profile.motors: the telemetry packet carries at most 10 motors")

    buttons = root.sub("buttons", BUTTON_KEYS)
    torch = buttons.integer("torch", low=0, high=BUTTON_COUNT - 1)
    camera = buttons.integer("camera_select", low=0, high=BUTTON_COUNT - 1)
    if torch == camera:
        raise ProfileError("profile.buttons: torch and camera_select must differ")

    assumptions = data.get("assumptions", [])
    if not isinstance(assumptions, list) or not all(isinstance(a, str) for a in assumptions):
        raise ProfileError("profile.assumptions: must be a list of key names")
    measured = _parse_measured(root, data, assumptions)
    return RobotProfile(
        name=root.string("name"),
        source=source,
        link=link_settings,
        channels=channels,
        motors=motors,
        torch_button=torch,
        camera_button=camera,
        track_width_m=root.sub("chassis", CHASSIS_KEYS).number("track_width_m", low=0.01),
        telemetry_speed_per_rad_s=si.number("telemetry_speed_per_rad_s", low=1e-9),
        telemetry_current_per_amp=si.number("telemetry_current_per_amp", low=1e-9),
        linear_axis_per_m_s=scales["linear"],
        rotation_axis_per_rad_s=scales["rotation"],
        assumptions=tuple(assumptions),
        extension=(
            _parse_extension(root.sub("extension", EXTENSION_KEYS), frame_types)
            if root.optional("extension")
            else None
        ),
        video=(
            _parse_video(root.sub("video", VIDEO_KEYS))
            if root.optional("video")
            else VideoSettings()
        ),
        cameras=_parse_cameras(root, tuple(cameras)),
        arm=_parse_arm(root.sub("arm", ARM_KEYS), motors) if root.optional("arm") else None,
        navigation=(
            _parse_navigation(root.sub("navigation", NAVIGATION_KEYS))
            if root.optional("navigation")
            else NavigationSettings()
        ),
        measured=measured,
        urdf=_parse_urdf(root, source),
    )


def _parse_urdf(root: TableReader, source: str) -> Path | None:
    """The `urdf` key: the robot's description, a file; relative to the profile's folder."""
    if not root.optional("urdf"):
        return None
    text = root.string("urdf")
    path = Path(text).expanduser()
    if not path.is_absolute() and source.startswith("<"):
        raise ProfileError(f"{root.where}.urdf: a relative path needs the profile's file")
    if not path.is_absolute():
        path = Path(source).parent / path
    if not path.is_file():
        raise ProfileError(
            f"{root.where}.urdf: no file {str(path)!r} (a relative path is from the "
            "profile's folder)"
        )
    return path


def _parse_measured(
    root: TableReader, data: dict[str, Any], assumptions: list[str]
) -> dict[str, Measurement]:
    """The `[measured."key"]` entries; each must name a key the profile holds."""
    if not root.optional("measured"):
        return {}
    table = root.sub("measured", None)
    measured: dict[str, Measurement] = {}
    for key, entry in table.table.items():
        where = f'profile.measured."{key}"'
        if not isinstance(entry, dict):
            raise ProfileError(f"{where}: must be a table (how, when, residual, ...)")
        reader = TableReader(entry, where, MEASUREMENT_KEYS)
        value: Any = data
        for part in key.split("."):
            if not isinstance(value, dict) or part not in value:
                raise ProfileError(f"{where}: names no key of this profile")
            value = value[part]
        if key in assumptions:
            raise ProfileError(f"{where}: also listed in assumptions; a key is one or the other")
        when = reader.table.get("when")
        if not isinstance(when, dt.datetime) or when.tzinfo is None:
            raise ProfileError(
                f"{where}.when: must be a date and time with its offset, e.g. 2025-06-01T12:00:00Z"
            )
        measured[key] = Measurement(
            key=key,
            how=reader.string("how"),
            when=when,
            residual=(reader.number("residual", low=0.0) if reader.optional("residual") else None),
            residual_unit=(
                reader.string("residual_unit") if reader.optional("residual_unit") else None
            ),
            samples=(
                reader.integer("samples", low=1, high=2**31 - 1)
                if reader.optional("samples")
                else None
            ),
        )
    return measured


# ---- writing -----------------------------------------------------------------------------
