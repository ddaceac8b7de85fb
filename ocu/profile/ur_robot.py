"""A RobotProfile for a Universal Robots arm, built from its UrArmProfile (docs/ur.md).

The console, the headless console and the control core take an `ocu.profile.RobotProfile`;
this builds one for a UR: six motors that report their position, six velocity channels named
after the joints (rad/s), the arm's joints and frames, and link timing chosen for a UR
controller, and its URDF (ocu.profile.ur_urdf). No chassis, drive, cameras, torch or protocol
extension. Every timing value and
why it was chosen is in docs/ur.md ("The UR link"); the assumed ones are listed in
`assumptions` so that `provenance()` says so.
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

from ocu.profile.description import ArmSettings, Motor, RobotProfile
from ocu.profile.hardware import Channel, FrameTypes, LinkSettings
from ocu.profile.ur import UrArmProfile, load_ur_profile, shipped_ur_profiles
from ocu.profile.ur_urdf import ur_urdf_path

#: The realtime port: the one whose packets say the link is alive, and where URScript goes.
UR_REALTIME_PORT = 30003
#: speedj is streamed at most this fast: seed 004's driver streams at the CB3's 125 Hz, and
#: an e-Series (500 Hz) takes a 125 Hz stream (each command runs until the next).
UR_SEND_RATE_HZ = 125.0
#: speedj's `t`: the controller ends the command (and brakes) this long after the last one,
#: the robot-side watchdog. 7.5 periods at 125 Hz: a few late sends do not make it brake.
UR_SPEEDJ_T_S = 0.06
#: The link hands the newest realtime state on at most this often (the controller sends 125 or
#: 500 a second): each reading goes through the console model, its plots and the position
#: controller, and a Python console kept its 50 Hz control cycle only at this rate.
UR_TELEMETRY_HZ = 50.0
#: No realtime packet for this long: LINK LOST (62 periods at 125 Hz, 250 at 500 Hz).
UR_LINK_LOST_AFTER_S = 0.5
#: No heartbeat from the commanding thread for this long: zero velocities (as the Engineer).
UR_GUI_ALIVE_TIMEOUT_S = 0.5
#: An e-stop: stopj at once and repeated this many times in all, over the window.
UR_ESTOP_REPEATS = 3
UR_ESTOP_WINDOW_S = 0.02
#: Raw positions in telemetry records (RawMotor.position) are micro-radians.
UR_TICKS_PER_RAD = 1e6
#: The operator's default top joint speed (rad/s), below every UR joint's top speed.
UR_DEFAULT_MAX_RAD_S = 0.5

UR_ASSUMPTIONS = (
    "link.send_rate_hz",
    "link.telemetry_rate_hz",
    "link.robot_watchdog_s",
    "link.link_lost_after_s",
    "link.gui_alive_timeout_s",
    "link.estop_repeats",
    "link.estop_window_s",
    "channels.*.default_max",
    "arm",
)


def ur_link_settings(arm: UrArmProfile, host: str = "127.0.0.1") -> LinkSettings:
    """The link timing for a UR controller at `host` (values: docs/ur.md "The UR link")."""
    send_rate = min(UR_SEND_RATE_HZ, arm.realtime_hz)
    return LinkSettings(
        address=host,
        port=UR_REALTIME_PORT,
        send_rate_hz=send_rate,
        send_rate_min_hz=min(50.0, send_rate),
        send_rate_max_hz=arm.realtime_hz,
        robot_watchdog_s=UR_SPEEDJ_T_S,
        telemetry_rate_hz=min(UR_TELEMETRY_HZ, arm.realtime_hz),
        telemetry_tick_hz=arm.realtime_hz,
        link_lost_after_s=UR_LINK_LOST_AFTER_S,
        gui_alive_timeout_s=UR_GUI_ALIVE_TIMEOUT_S,
        estop_repeats=UR_ESTOP_REPEATS,
        estop_window_s=UR_ESTOP_WINDOW_S,
        default_video_bitrate=0.0,
        camera_names=(),
        # A UR has no packet IDs of the Engineer's kind; zeros say "none".
        frame_types=FrameTypes(rcp=0, telemetry=0, video=0),
    )


def ur_robot_profile(arm: UrArmProfile, host: str = "127.0.0.1") -> RobotProfile:
    """The RobotProfile of a UR arm: six positioned motors, six joint velocity channels."""
    channels: dict[str, Channel] = {}
    motors: dict[str, Motor] = {}
    for index, joint in enumerate(arm.joints):
        channels[joint.name] = Channel(
            name=joint.name,
            axis=index,
            axis_per_unit=1.0,
            unit="rad/s",
            min_speed=0.0,
            default_max=min(UR_DEFAULT_MAX_RAD_S, joint.max_speed_rad_s),
            hard_max=joint.max_speed_rad_s,
        )
        limits_rad = (
            (joint.min_rad, joint.max_rad)
            if joint.min_rad is not None and joint.max_rad is not None
            else None
        )
        motors[joint.name] = Motor(
            name=joint.name,
            device_id=index + 1,
            channel=joint.name,
            track=None,
            ticks_per_rad=UR_TICKS_PER_RAD,
            zero_offset_ticks=0,
            limits_rad=limits_rad,
            limits_deg=(
                (math.degrees(limits_rad[0]), math.degrees(limits_rad[1]))
                if limits_rad is not None
                else None
            ),
        )
    arm_settings = ArmSettings(
        # The ROS convention's frames (issue 22): base_link is the controller's base frame
        # turned 180° about z; tool0 the flange.
        base_link="base_link",
        tool_link="tool0",
        camera_link=None,
        joints=arm.joint_names,
        linear_speed_m_s=0.05,
        max_linear_speed_m_s=0.25,
        pitch_speed_rad_s=0.2,
        max_pitch_speed_rad_s=0.5,
        acceleration_rad_s2=arm.max_acceleration_rad_s2,
        joint_limit_margin_rad=math.radians(2.0),
        # Condition numbers of the task Jacobian, lengths in units of the longest link (as
        # the Engineer's: the same scale whatever the arm's size).
        singularity_slow=17.0,
        singularity_stop=30.0,
        clearance_m=0.05,
        slow_distance_m=0.1,
        ground_z_m=None,
        twist_timeout_s=0.1,
        poses={},
        tool_axis="z",
    )
    return RobotProfile(
        name=arm.name,
        source=arm.source,
        link=ur_link_settings(arm, host),
        channels=channels,
        motors=motors,
        torch_button=0,
        camera_button=0,
        track_width_m=0.0,
        telemetry_speed_per_rad_s=1.0,
        telemetry_current_per_amp=1.0,
        linear_axis_per_m_s=1.0,
        rotation_axis_per_rad_s=1.0,
        assumptions=UR_ASSUMPTIONS,
        extension=None,
        cameras=(),
        arm=arm_settings,
        # Its description: the URDF written from the DH parameters (ocu.profile.ur_urdf).
        urdf=ur_urdf_path(arm),
    )


def load_ur_arm(name: str | None) -> UrArmProfile | None:
    """The UR arm `--profile` names (a shipped name, or a file in the UR format: it has a
    `series`), else None (an Engineer profile); ProfileError for a bad UR file."""
    if name is None:
        return None
    if name in shipped_ur_profiles():
        return load_ur_profile(name)
    path = Path(name)
    if path.suffix == ".toml" and path.is_file():
        try:
            data = tomllib.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
            return None  # load_profile says what is wrong with it
        if "series" in data:
            return load_ur_profile(path)
    return None
