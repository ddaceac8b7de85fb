"""A RobotProfile for the xArm 1S, built from its XarmProfile (docs/xarm.md).

Six motors that report their position (the servos, device ID = servo ID, raw = servo units),
six velocity channels named after the joints (rad/s: the link turns them into short moves),
link timing from the xArm profile's [timing], the arm's Cartesian settings and its URDF
(ocu.profile.xarm_urdf). No chassis, drive, cameras, torch or protocol extension. The assumed
values are listed in `assumptions`.
"""

from __future__ import annotations

import math

from ocu.profile.description import ArmSettings, Motor, RobotProfile
from ocu.profile.hardware import Channel, FrameTypes, LinkSettings
from ocu.profile.xarm import CENTRE_UNITS, XarmProfile
from ocu.profile.xarm_urdf import ARM_JOINTS, xarm_urdf_path

#: No heartbeat from the commanding thread for this long: motion stops (as the Engineer).
XARM_GUI_ALIVE_TIMEOUT_S = 0.5
#: An e-stop: the stop move at once and repeated this many times in all, over the window
#: (a serial line loses nothing, but garbage on it can spoil a frame).
XARM_ESTOP_REPEATS = 3
XARM_ESTOP_WINDOW_S = 0.02
#: The operator's default top joint speed (rad/s).
XARM_DEFAULT_MAX_RAD_S = 0.5

XARM_ASSUMPTIONS = (
    "link.send_rate_hz",
    "link.telemetry_rate_hz",
    "link.robot_watchdog_s",
    "link.link_lost_after_s",
    "link.gui_alive_timeout_s",
    "link.estop_repeats",
    "link.estop_window_s",
    "channels.*.default_max",
    "motors.*.zero_offset_ticks",
    "arm",
)


def xarm_link_settings(arm: XarmProfile, port: str = "") -> LinkSettings:
    """The link timing of an xArm on serial device `port` (values: the profile's [timing])."""
    timing = arm.timing
    send_rate = 1.0 / timing.jog_period_s
    return LinkSettings(
        address=port,
        port=0,  # a serial device has no port number
        send_rate_hz=send_rate,
        send_rate_min_hz=min(5.0, send_rate),
        send_rate_max_hz=max(50.0, send_rate),
        # A jog move's time: how long the servos go on after the last move (robot side).
        robot_watchdog_s=timing.jog_move_s,
        # While the arm moves (when the console's controllers judge the readings' age) the
        # positions come at the slower rate.
        telemetry_rate_hz=1.0 / max(timing.read_period_s, timing.read_period_moving_s),
        telemetry_tick_hz=1.0 / timing.read_period_s,
        link_lost_after_s=timing.link_lost_after_s,
        gui_alive_timeout_s=XARM_GUI_ALIVE_TIMEOUT_S,
        estop_repeats=XARM_ESTOP_REPEATS,
        estop_window_s=XARM_ESTOP_WINDOW_S,
        default_video_bitrate=0.0,
        camera_names=(),
        frame_types=FrameTypes(rcp=0, telemetry=0, video=0),
    )


def xarm_robot_profile(arm: XarmProfile, port: str = "") -> RobotProfile:
    """The RobotProfile of an xArm: six positioned servos, six joint velocity channels."""
    channels: dict[str, Channel] = {}
    motors: dict[str, Motor] = {}
    for index, joint in enumerate(arm.joints):
        channels[joint.name] = Channel(
            name=joint.name,
            axis=index,
            axis_per_unit=1.0,
            unit="rad/s",
            min_speed=0.0,
            default_max=min(XARM_DEFAULT_MAX_RAD_S, joint.max_speed_rad_s),
            hard_max=joint.max_speed_rad_s,
        )
        ends = sorted(
            (arm.angle_rad(joint, joint.min_units), arm.angle_rad(joint, joint.max_units))
        )
        motors[joint.name] = Motor(
            name=joint.name,
            device_id=joint.servo,
            channel=joint.name,
            track=None,
            ticks_per_rad=arm.units_per_rad,
            zero_offset_ticks=CENTRE_UNITS + joint.offset_units,
            limits_rad=(ends[0], ends[1]),
            limits_deg=(math.degrees(ends[0]), math.degrees(ends[1])),
        )
    return RobotProfile(
        name=arm.name,
        source=arm.source,
        link=xarm_link_settings(arm, port),
        channels=channels,
        motors=motors,
        torch_button=0,
        camera_button=0,
        track_width_m=0.0,
        telemetry_speed_per_rad_s=1.0,
        telemetry_current_per_amp=1.0,
        linear_axis_per_m_s=1.0,
        rotation_axis_per_rad_s=1.0,
        assumptions=XARM_ASSUMPTIONS,
        extension=None,
        cameras=(),
        arm=xarm_arm_settings(),
        # Its description: the URDF written from the profile (ocu.profile.xarm_urdf).
        urdf=xarm_urdf_path(arm),
    )


def xarm_arm_settings() -> ArmSettings:
    """The xArm in Cartesian space: seed 003's four joints, speeds for a desk-sized arm."""
    return ArmSettings(
        base_link="base_link",
        tool_link="tool0",
        camera_link=None,
        joints=ARM_JOINTS,
        linear_speed_m_s=0.02,
        max_linear_speed_m_s=0.1,
        pitch_speed_rad_s=0.2,
        max_pitch_speed_rad_s=0.5,
        acceleration_rad_s2=2.0,
        joint_limit_margin_rad=math.radians(2.0),
        # Condition numbers in units of the longest link, as the Engineer's and the UR's.
        singularity_slow=17.0,
        singularity_stop=30.0,
        clearance_m=0.02,
        slow_distance_m=0.05,
        ground_z_m=0.0,  # the table the arm stands on
        twist_timeout_s=0.1,
        poses={},
        tool_axis="x",
    )
