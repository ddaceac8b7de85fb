"""The simulated robot's motion: joints within their limits, the watchdog, tracks and pose.

Pure: no sockets, no threads and no clock of its own; every call says what time it is
(monotonic seconds), so tests step it by hand. The robot follows the latest command until
`robot_watchdog_s` passes without one, then stops every motor until the next command.
Below a channel's `min_speed` a servo does not start; the drive pair moves together; the
`locked_while_driving` channels (the waist) do not move while the chassis does.

In a world (ocu.nav.world) the chassis is the profile's footprint: a motion that would make
it overlap a wall or a box is not made — the robot stops at the contact, its tracks stall
(telemetry reports them still) and `collision at (x, y)` is logged at WARNING once per
contact; a command that moves it away frees it.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass

from ocu.nav.geometry import Pose, advance
from ocu.nav.world import EMPTY_WORLD, World
from ocu.profile import Motor, RobotProfile
from ocu.protocol.mapping import track_speeds
from ocu.records import Command

log = logging.getLogger("ocu.sim")

# Simulator model constants, not robot facts: currents of the right order for small servos.
JOINT_IDLE_CURRENT_A = 0.3
JOINT_CURRENT_A_PER_RAD_S = 2.0
TRACK_IDLE_CURRENT_A = 0.5
TRACK_CURRENT_A_PER_M_S = 8.0
# Collision checks along the chassis' path: at most this far (m, or rad of turn) per check.
CONTACT_STEP_M = 0.01
CONTACT_STEP_RAD = 0.02


@dataclass(frozen=True)
class MotorReading:
    """What one motor's sensors say, in SI units, before telemetry encodes it.

    Speeds are rad/s for joints and belt m/s for tracks; a track has no angle.
    """

    angle_rad: float | None
    speed: float
    speed_command: float
    current_a: float
    current_command_a: float
    at_lower_limit: bool
    at_upper_limit: bool
    watchdog_stopped: bool
    suppressed: bool


def limits_rad(motor: Motor) -> tuple[float, float]:
    """A motor's limits; unbounded when the profile gives none."""
    return motor.limits_rad if motor.limits_rad is not None else (-math.inf, math.inf)


def _current_a(idle_a: float, amps_per_speed: float, speed: float) -> float:
    return idle_a + amps_per_speed * abs(speed)


class RobotPhysics:
    """Joint angles, motor velocities and the chassis pose of one simulated robot."""

    def __init__(
        self,
        profile: RobotProfile,
        initial_joints: Mapping[str, float] | None = None,
        *,
        now_s: float = 0.0,
        world: World | None = None,
        turn_slip: float = 0.0,
    ) -> None:
        if not 0.0 <= turn_slip < 1.0:
            raise ValueError(f"turn_slip must be in [0, 1), got {turn_slip!r}")
        self.profile = profile
        # Tracks skid in a turn: the chassis turns this fraction less than its belts say
        # (the belts' speeds, which telemetry reports, are unchanged).
        self.turn_slip = turn_slip
        self.world = world if world is not None else EMPTY_WORLD
        self._footprint = profile.navigation.footprint
        if self.world.obstacles and self._footprint is None:
            raise ValueError("a world needs the profile's footprint ([navigation] table)")
        if self._footprint is not None:
            touched = self.world.touching(self._footprint, self.world.start)
            if touched is not None:
                raise ValueError(
                    f"the robot's start pose {tuple(round(v, 3) for v in self.world.start)} "
                    f"overlaps a {touched.kind} of {self.world.name}"
                )
        self._channel_motors = {
            motor.channel: motor for motor in profile.positioned_motors if motor.channel
        }
        self._drive = list(profile.drive_channels or ())
        self._locked = [name for name, ch in profile.channels.items() if ch.locked_while_driving]
        self._angles_rad = self._initial_angles(initial_joints or {})
        self._velocities = dict.fromkeys(profile.channels, 0.0)
        self._commanded = dict.fromkeys(profile.channels, 0.0)
        self._track_speeds_m_s = (0.0, 0.0)
        self._commanded_tracks_m_s = (0.0, 0.0)
        start = self.world.start
        self._pose = (start.x_m, start.y_m, start.heading_rad)
        self._in_contact = False
        # The belt speeds that ran into the obstacle: they stay stalled until they change.
        self._stalled: tuple[float, float] | None = None
        self._collisions = 0
        self._waist_suppressed = False
        self._command: Command | None = None
        self._last_command_s = now_s
        self._watchdog_stopped = False
        self._time_s = now_s

    def _initial_angles(self, initial: Mapping[str, float]) -> dict[str, float]:
        angles: dict[str, float] = {}
        for motor in self.profile.motors.values():
            if not motor.has_position:
                continue
            low, high = limits_rad(motor)
            angles[motor.name] = min(max(0.0, low), high)
        for name, angle_rad in initial.items():
            if name not in angles:
                raise ValueError(f"initial_joints: {name!r} is not a motor with a position")
            low, high = limits_rad(self.profile.motors[name])
            if not (math.isfinite(angle_rad) and low <= angle_rad <= high):
                raise ValueError(
                    f"initial_joints: {name}={angle_rad!r} rad outside [{low:.4f}, {high:.4f}]"
                )
            angles[name] = float(angle_rad)
        return angles

    # ---- state ------------------------------------------------------------------------------

    @property
    def time_s(self) -> float:
        """The time the state was last advanced to."""
        return self._time_s

    @property
    def joints_rad(self) -> dict[str, float]:
        """The angle of every motor with a position."""
        return dict(self._angles_rad)

    @property
    def velocities(self) -> dict[str, float]:
        """What each channel really moves at (after deadband, locks, limits and watchdog)."""
        return dict(self._velocities)

    @property
    def commanded_velocities(self) -> dict[str, float]:
        """What the command in force asks of each channel (zero after a watchdog stop)."""
        return dict(self._commanded)

    @property
    def track_speeds_m_s(self) -> tuple[float, float]:
        """Left and right belt speeds."""
        return self._track_speeds_m_s

    @property
    def pose(self) -> tuple[float, float, float]:
        """Ground truth of the chassis: x_m, y_m and heading_rad from where it started."""
        return self._pose

    @property
    def in_contact(self) -> bool:
        """Whether the chassis is pressed against an obstacle (its tracks stall)."""
        return self._in_contact

    @property
    def collisions(self) -> int:
        """How many times the chassis ran into an obstacle."""
        return self._collisions

    @property
    def watchdog_stopped(self) -> bool:
        """Whether the watchdog stopped every motor (until the next command)."""
        return self._watchdog_stopped

    @property
    def waist_suppressed(self) -> bool:
        """Whether a locked_while_driving channel is commanded while the chassis moves."""
        return self._waist_suppressed

    @property
    def all_stopped(self) -> bool:
        """Whether no channel moves."""
        return all(speed == 0.0 for speed in self._velocities.values())

    # ---- time -------------------------------------------------------------------------------

    def apply(self, command: Command, now_s: float) -> None:
        """Follow a new command from now_s on (it also feeds the watchdog)."""
        # Integrate the old command up to now so the new one takes effect exactly from now.
        self.advance(now_s)
        if self._watchdog_stopped:
            log.info("RCP received again: watchdog stop cleared")
            self._watchdog_stopped = False
        self._command = command
        self._last_command_s = now_s
        self._update_velocities()

    def advance(self, now_s: float) -> None:
        """Move everything up to now_s; the watchdog stops motors at its exact expiry."""
        if now_s <= self._time_s:
            return
        watchdog_s = self.profile.link.robot_watchdog_s
        expiry_s = self._last_command_s + watchdog_s
        if self._command is not None and not self._watchdog_stopped and expiry_s < now_s:
            # Move only until the watchdog fired, even when this step came late.
            stop_s = max(self._time_s, expiry_s)
            self._integrate(stop_s - self._time_s)
            self._time_s = stop_s
            self._watchdog_stopped = True
            log.info("watchdog: no RCP for %.2f s, all motors stopped", watchdog_s)
            self._update_velocities()
        self._integrate(now_s - self._time_s)
        self._time_s = now_s
        self._update_velocities()

    def _update_velocities(self) -> None:
        command = self._command if not self._watchdog_stopped else None
        channels = self.profile.channels
        commanded = {
            name: command.velocity(name) if command is not None else 0.0 for name in channels
        }
        # Servo deadband: below min_speed a servo does not start moving. The tracks move as a
        # pair: a turn fast enough to start them carries a slow linear speed along (and the
        # other way round), as the OCU's drive scaling assumes (seed 002, eq. 5.4).
        effective = {
            name: speed if abs(speed) >= channels[name].min_speed else 0.0
            for name, speed in commanded.items()
        }
        if any(effective[name] != 0.0 for name in self._drive):
            for name in self._drive:
                effective[name] = commanded[name]
        # The vendor server refuses to turn the waist while the chassis moves.
        driving = any(effective[name] != 0.0 for name in self._drive)
        self._waist_suppressed = driving and any(effective[name] != 0.0 for name in self._locked)
        if driving:
            for name in self._locked:
                effective[name] = 0.0
        for channel, motor in self._channel_motors.items():
            low_rad, high_rad = limits_rad(motor)
            angle_rad = self._angles_rad[motor.name]
            speed = effective[channel]
            if (angle_rad <= low_rad and speed < 0.0) or (angle_rad >= high_rad and speed > 0.0):
                effective[channel] = 0.0
        self._commanded = commanded
        self._velocities = effective
        self._track_speeds_m_s = track_speeds(self.profile, effective)
        if self._stalled is not None and self._track_speeds_m_s == self._stalled:
            self._track_speeds_m_s = (0.0, 0.0)  # still pushing against the obstacle
        self._commanded_tracks_m_s = track_speeds(self.profile, commanded)

    def _integrate(self, dt_s: float) -> None:
        if dt_s <= 0.0:
            return
        for channel, motor in self._channel_motors.items():
            speed_rad_s = self._velocities[channel]
            if speed_rad_s == 0.0:
                continue
            low_rad, high_rad = limits_rad(motor)
            angle_rad = self._angles_rad[motor.name] + speed_rad_s * dt_s
            self._angles_rad[motor.name] = min(max(angle_rad, low_rad), high_rad)
        left_m_s, right_m_s = self._track_speeds_m_s
        if left_m_s == 0.0 and right_m_s == 0.0:
            return
        speed_m_s = (left_m_s + right_m_s) / 2.0
        turn_rad_s = (right_m_s - left_m_s) / self.profile.track_width_m * (1.0 - self.turn_slip)
        footprint = self._footprint
        if footprint is None or not self.world.obstacles:
            moved = advance(Pose(*self._pose), speed_m_s * dt_s, turn_rad_s * dt_s)
            self._pose = (moved.x_m, moved.y_m, moved.heading_rad)
            return
        # In small steps, so a fast robot cannot jump through a thin wall.
        steps = max(
            1,
            math.ceil(abs(speed_m_s) * dt_s / CONTACT_STEP_M),
            math.ceil(abs(turn_rad_s) * dt_s / CONTACT_STEP_RAD),
        )
        h = dt_s / steps
        pose = Pose(*self._pose)
        for _ in range(steps):
            moved = advance(pose, speed_m_s * h, turn_rad_s * h)
            if self.world.touching(footprint, moved) is not None:
                self._contact(pose)
                break
            pose = moved
            self._in_contact = False
            self._stalled = None
        self._pose = (pose.x_m, pose.y_m, pose.heading_rad)

    def place(self, pose: Pose) -> None:
        """Put the chassis somewhere (a test's or a benchmark's hand); ValueError if that
        overlaps an obstacle."""
        if self._footprint is not None:
            touched = self.world.touching(self._footprint, pose)
            if touched is not None:
                raise ValueError(f"{tuple(pose)} overlaps a {touched.kind}")
        self._pose = (pose.x_m, pose.y_m, pose.heading_rad)
        self._in_contact = False
        self._stalled = None

    def _contact(self, pose: Pose) -> None:
        """The chassis ran into something: it stops there and its tracks stall."""
        if not self._in_contact:
            self._collisions += 1
            log.warning("collision at (%.2f, %.2f)", pose.x_m, pose.y_m)
        self._in_contact = True
        self._stalled = self._track_speeds_m_s
        self._track_speeds_m_s = (0.0, 0.0)

    # ---- sensors ----------------------------------------------------------------------------

    def reading(self, motor: Motor) -> MotorReading:
        """What a motor's sensors say now (true values: noise is the telemetry's business)."""
        angle_rad: float | None = None
        at_lower = at_upper = suppressed = False
        if motor.track is not None:
            index = 0 if motor.track == "left" else 1
            speed = self._track_speeds_m_s[index]
            speed_command = self._commanded_tracks_m_s[index]
            idle_a, amps_per_speed = TRACK_IDLE_CURRENT_A, TRACK_CURRENT_A_PER_M_S
        else:
            speed = self._velocities[motor.channel] if motor.channel else 0.0
            speed_command = self._commanded[motor.channel] if motor.channel else 0.0
            idle_a, amps_per_speed = JOINT_IDLE_CURRENT_A, JOINT_CURRENT_A_PER_RAD_S
            if motor.has_position:
                angle_rad = self._angles_rad[motor.name]
                low_rad, high_rad = limits_rad(motor)
                at_lower, at_upper = angle_rad <= low_rad, angle_rad >= high_rad
            suppressed = motor.channel in self._locked and self._waist_suppressed
        return MotorReading(
            angle_rad=angle_rad,
            speed=speed,
            speed_command=speed_command,
            current_a=_current_a(idle_a, amps_per_speed, speed),
            current_command_a=_current_a(idle_a, amps_per_speed, speed_command),
            at_lower_limit=at_lower,
            at_upper_limit=at_upper,
            watchdog_stopped=self._watchdog_stopped,
            suppressed=suppressed,
        )
