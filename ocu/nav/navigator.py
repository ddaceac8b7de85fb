"""The Navigator: odometry, the latest scan, the occupancy grid, the safety zones and the
assisted modes of one robot, together (no Qt, no ROS; thread-safe).

The console model and the ROS node each hold one and feed it what the link reports —
telemetry (track speeds, the round trip), extension status (the IMU heading), range scans
(from the robot, and from other ROS nodes: each source keeps its own newest scan, and the
zones take the nearest obstacle of every fresh one), and every command that went on the
wire — and ask it three things:

- `estimate()`: where the robot is, how sure that is, whether it is stale;
- `guard(v, ω)`: what the safety zones let through of a drive command, with the status
  text ("slowed: obstacle 0.74 m ahead", "zones off: no range data", "ZONES OVERRIDDEN");
- `assist_step()`: what an assisted mode commands now, or that it stopped and why.

The override is deliberate and short: `override_zones()` arms it; it holds for the next
motion only (until the drive command is zero again), and lapses if no motion follows
within `OVERRIDE_ARM_S`.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from ocu.nav.assist import AssistCommand, AssistError, LinearShuttle, PathFollower
from ocu.nav.geometry import ORIGIN, Points, Pose
from ocu.nav.grid import OccupancyGrid
from ocu.nav.odometry import Odometry, OdometryEstimate
from ocu.nav.scan import scan_points
from ocu.nav.tracking import Trajectory, along_path
from ocu.nav.zones import (
    ZoneDecision,
    apply_zones,
    cap_ratio,
    fastest_point_speed,
)
from ocu.profile import RobotProfile
from ocu.records import Command, ScanFrame, StatusFrame, TelemetryFrame

# What the robot covers before a command composed now takes effect, besides the link delay:
# the console recomposes at 20 Hz, and one period more for the command to go out.
COMMAND_LAG_S = 0.1
OVERRIDE_ARM_S = 5.0
TRAIL_STEP_M = 0.05
# The occupancy grid takes at most one scan per this period (a 10 Hz sensor: every other):
# a map the operator looks at needs no more, and each scan costs ~4 ms of the GUI thread.
# The safety zones always use the newest scan itself.
GRID_PERIOD_S = 0.2
# A motion the zones stopped stays stopped until the travel to contact clears the stop distance
# by this much more: the margin moves with each scan's age and the link's jitter, and without
# it the decision flips between "stopped" and "slowed" at the boundary, the robot inching on in
# spurts of the innermost zone's speed.
STOP_HYSTERESIS_M = 0.05
TRAIL_LENGTH = 5000

ZONES_OFF_NO_DATA = "zones off: no range data"
# Scans came and stopped (a sensor, its node or the link failed): nothing is known of what is
# ahead now, so the drive is held to the innermost zone's caps (Nav2's collision monitor stops
# outright on a source timeout; a crawler the operator watches may creep, and Z overrides).
ZONES_BLIND = "zones: range data lost"
ZONES_OFF_NO_FOOTPRINT = "zones off: the profile has no footprint"
ZONES_OVERRIDDEN = "ZONES OVERRIDDEN"
ZONES_CLEAR = "zones: clear"


@dataclass(frozen=True)
class ZoneState:
    """What the zones did to the last drive command, and what the status bar says."""

    decision: ZoneDecision | None
    active: bool
    overridden: bool
    text: str
    # Range data came and stopped: the drive is held to the innermost zone's caps.
    blind: bool = False

    @property
    def limiting(self) -> bool:
        """Whether the zones changed the command."""
        return self.decision is not None and self.decision.limited and not self.overridden


NO_ZONES = ZoneState(None, False, False, ZONES_OFF_NO_DATA)


class Navigator:
    """See the module docstring. `grid=False` skips the occupancy grid (the ROS node)."""

    # A part of the console model: the GUI reaches it under the model's lock (ocu.core.guard).
    guarded = True

    def __init__(
        self,
        profile: RobotProfile,
        *,
        clock: Callable[[], float] = time.monotonic,
        grid: bool = True,
    ) -> None:
        self.profile = profile
        self.clock = clock
        navigation = profile.navigation
        self.settings = navigation
        self.footprint = navigation.footprint
        self.drive = profile.drive_channels
        linear = profile.channels[self.drive[0]] if self.drive else None
        turn = profile.channels[self.drive[1]] if self.drive else None
        self._lock = threading.RLock()
        self.odometry = Odometry(
            profile.track_width_m,
            navigation.odometry,
            min_linear_m_s=linear.min_speed if linear else 0.0,
            min_angular_rad_s=turn.min_speed if turn else 0.0,
            watchdog_s=profile.link.robot_watchdog_s,
            now_s=clock(),
        )
        self._tracks = {
            motor.track: motor.name for motor in profile.motors.values() if motor.track is not None
        }
        self.grid = OccupancyGrid() if grid else None
        self._grid_at: float | None = None
        self.trail: deque[tuple[float, float]] = deque(maxlen=TRAIL_LENGTH)
        # The newest scan of each source (the robot's sensor; each ROS publisher and frame)
        # with its points in the robot's frame: the zones use every fresh one.
        self._sources: dict[str, tuple[ScanFrame, Points]] = {}
        self._scan: ScanFrame | None = None
        self._one_way_s = 0.0
        self._assist: LinearShuttle | PathFollower | None = None
        self._assist_external = False
        self._override = "off"
        self._override_at = 0.0
        self._zones = NO_ZONES
        # The motion (signs of v and ω) the zones last stopped, held with the hysteresis.
        self._stopped_motion: tuple[float, float] | None = None
        self.revision = 0

    # ---- what the link reports -------------------------------------------------------------

    def on_telemetry(self, frame: TelemetryFrame) -> None:
        """Track speeds and the round trip this telemetry took."""
        with self._lock:
            self._round_trip(frame.delay_s)
            left = frame.readings.get(self._tracks.get("left", ""))
            right = frame.readings.get(self._tracks.get("right", ""))
            if left is None or right is None:
                return
            # A track's speed reading is its belt speed in m/s.
            self.odometry.on_tracks(frame.received_at, left.speed_rad_s, right.speed_rad_s)
            self.revision += 1

    def on_round_trip(self, round_trip_s: float | None) -> None:
        """The link's measured round trip (its statistics)."""
        with self._lock:
            self._round_trip(round_trip_s)

    def _round_trip(self, round_trip_s: float | None) -> None:
        if round_trip_s is not None and math.isfinite(round_trip_s) and round_trip_s >= 0.0:
            self.odometry.set_round_trip(round_trip_s)
            self._one_way_s = round_trip_s / 2.0

    def on_status(self, frame: StatusFrame) -> None:
        """The extension's status: the IMU heading, when the robot reports one."""
        yaw = frame.yaw_rad
        if yaw is None:
            return
        with self._lock:
            self.odometry.on_heading(frame.received_at, yaw)
            self.revision += 1

    def on_command(self, command: Command, sent_at: float) -> None:
        """A command went on the wire (repeats included: they feed the robot's watchdog)."""
        if self.drive is None:
            return
        with self._lock:
            self.odometry.on_command(
                sent_at, command.velocity(self.drive[0]), command.velocity(self.drive[1])
            )

    def on_scan(
        self,
        scan: ScanFrame,
        *,
        source: str | None = None,
        mount_xy_m: tuple[float, float] | None = None,
    ) -> bool:
        """A range scan from `source` (default: the scan's own, "robot" or "ros"), its sensor
        at `mount_xy_m` on the chassis facing along `angle_min_rad`'s zero (default: the
        profile's sensor mount). Each source keeps its newest scan; True (always taken)."""
        with self._lock:
            mount = self.settings.scan_mount_xy_m if mount_xy_m is None else mount_xy_m
            self._sources[scan.source if source is None else source] = (
                scan,
                scan_points(scan, mount),
            )
            self._scan = scan
            last = self._grid_at
            # (a tenth of slack: a 10 Hz sensor's scans arrive a little early or late)
            due = last is None or not 0.0 <= scan.received_at - last < 0.9 * GRID_PERIOD_S
            if self.grid is not None and due:
                taken = self.odometry.estimate(scan.received_at - self._one_way_s).pose
                self.grid.integrate(scan, taken, mount)
                self._grid_at = scan.received_at
            self.revision += 1
            return True

    def forget_scans(self) -> None:
        """A new connection: no scan yet (the zones are off until one comes, not blind)."""
        with self._lock:
            self._sources.clear()
            self._scan = None
            self._stopped_motion = None
            self.revision += 1

    def set_time_scale(self, scale: float) -> None:
        """Robot seconds per second of the events' clock (a replay's speed)."""
        if not (math.isfinite(scale) and scale > 0.0):
            raise ValueError(f"time scale must be > 0, got {scale!r}")
        with self._lock:
            self.odometry.time_scale = scale

    def reset_odometry(self, pose: Pose = ORIGIN) -> None:
        """The operator's reset: pose zero, no uncertainty; the map and trail start over."""
        with self._lock:
            self.odometry.reset(self.clock(), pose)
            if self.grid is not None:
                self.grid.clear()
                self._grid_at = None
            self.trail.clear()
            self.stop_assist("odometry reset")
            self.revision += 1

    # ---- what the views and the console ask -----------------------------------------------

    def estimate(self, now: float | None = None) -> OdometryEstimate:
        """The pose now (the trail grows as the robot moves)."""
        with self._lock:
            estimate = self.odometry.estimate(self.clock() if now is None else now)
            x, y = estimate.pose.x_m, estimate.pose.y_m
            if not self.trail or math.dist(self.trail[-1], (x, y)) >= TRAIL_STEP_M:
                self.trail.append((x, y))
            return estimate

    @property
    def one_way_s(self) -> float:
        """Half the link's measured round trip."""
        with self._lock:
            return self._one_way_s

    def scan(self) -> tuple[ScanFrame | None, Points]:
        """The latest scan, and the points of every fresh source in the robot's frame (all
        of the latest's when none is fresh)."""
        with self._lock:
            if self._scan is None:
                return None, np.zeros((0, 2))
            fresh = self._fresh(self.clock())
            if not fresh:
                latest = max(self._sources.values(), key=lambda entry: entry[0].received_at)
                return self._scan, latest[1]
            return self._scan, np.concatenate([points for _, points in fresh.values()])

    def scan_sources(self) -> list[str]:
        """The sources that sent a scan on this connection."""
        with self._lock:
            return sorted(self._sources)

    def _fresh(self, now: float) -> dict[str, tuple[ScanFrame, Points]]:
        """The sources whose newest scan arrived within `scan_stale_after_s`."""
        limit = self.settings.scan_stale_after_s
        return {
            name: entry
            for name, entry in self._sources.items()
            if now - entry[0].received_at <= limit
        }

    def scan_age_s(self, now: float | None = None) -> float | None:
        """How old the latest scan is (from its capture), None without one."""
        with self._lock:
            if self._scan is None:
                return None
            now = self.clock() if now is None else now
            return now - self._scan.received_at + self._one_way_s

    # ---- the safety zones ------------------------------------------------------------------

    def override_zones(self) -> None:
        """The operator's deliberate override: the zones let the next motion through."""
        with self._lock:
            self._override = "armed"
            self._override_at = self.clock()

    def cancel_override(self) -> None:
        """End an override (an emergency stop, a halt)."""
        with self._lock:
            self._override = "off"

    @property
    def zones_overridden(self) -> bool:
        """Whether the override is armed or in force."""
        with self._lock:
            if self._override == "armed" and self.clock() - self._override_at > OVERRIDE_ARM_S:
                self._override = "off"
            return self._override != "off"

    @property
    def zones(self) -> ZoneState:
        """What the zones did to the last command guarded."""
        with self._lock:
            return self._zones

    def guard(self, linear_m_s: float, angular_rad_s: float, now: float | None = None) -> ZoneState:
        """What the zones let through of (v, ω): `state.decision` holds the speeds."""
        with self._lock:
            now = self.clock() if now is None else now
            moving = linear_m_s != 0.0 or angular_rad_s != 0.0
            overridden = self.zones_overridden
            if overridden:
                if moving:
                    self._override = "active"
                elif self._override == "active":
                    self._override = "off"
                    overridden = False
            passed = ZoneDecision(linear_m_s, angular_rad_s)
            if self.footprint is None:
                state = ZoneState(passed, False, False, ZONES_OFF_NO_FOOTPRINT)
            elif not self._sources:
                state = ZoneState(passed, False, overridden, ZONES_OFF_NO_DATA)
            else:
                # Staleness counts from arrival (what the OCU has heard since), not from the
                # capture: a round-trip estimate must not shorten the time a sensor is given.
                fresh = self._fresh(now)
                stale = sorted(set(self._sources) - set(fresh))
                state = self._apply(linear_m_s, angular_rad_s, fresh, overridden, now)
                if stale:
                    state = self._blind(state, stale, overridden)
            if overridden:
                distance = state.decision.message() if state.decision is not None else ""
                detail = f": {distance.split(': ', 1)[-1]}" if distance else ""
                state = ZoneState(passed, state.active, True, ZONES_OVERRIDDEN + detail)
            self._zones = state
            return state

    def _blind(self, state: ZoneState, stale: list[str], overridden: bool) -> ZoneState:
        """The fresh sources' decision further held to the innermost zone's caps: a source
        stopped sending, and nothing is known of what it saw."""
        assert state.decision is not None
        zones = self.settings.zones
        before = state.decision
        v, w = cap_ratio(
            before.linear_m_s,
            before.angular_rad_s,
            zones.max_linear_m_s[0],
            zones.max_angular_rad_s[0],
        )
        if before.limited and (v, w) == (before.linear_m_s, before.angular_rad_s):
            decision = before  # the fresh sources' obstacle holds it down already
            text = before.message()
        else:
            limited = before.limited or (v, w) != (before.linear_m_s, before.angular_rad_s)
            decision = ZoneDecision(
                v, w, before.distance_m, before.direction, zone=0, limited=limited
            )
            text = f"{ZONES_BLIND}: at most {zones.max_linear_m_s[0]:.2f} m/s"
        if len(self._sources) > 1:
            text += f" ({', '.join(stale)} silent)"
        return ZoneState(decision, True, overridden, text, blind=True)

    def _apply(
        self,
        linear: float,
        angular: float,
        fresh: dict[str, tuple[ScanFrame, Points]],
        overridden: bool,
        now: float,
    ) -> ZoneState:
        """The zones for the nearest obstacle of every fresh source."""
        assert self.footprint is not None
        if not fresh:
            return ZoneState(ZoneDecision(linear, angular), True, overridden, ZONES_CLEAR)
        points = np.concatenate([p for _, p in fresh.values()])
        # The oldest fresh scan sets the margin: its points may have come closest since.
        age_s = now - min(scan.received_at for scan, _ in fresh.values()) + self._one_way_s
        current = self.odometry.estimate(self.clock())
        speed = max(
            fastest_point_speed(self.footprint, linear, angular),
            fastest_point_speed(self.footprint, current.linear_m_s, current.angular_rad_s),
        )
        margin = speed * (age_s + self._one_way_s + COMMAND_LAG_S)
        motion = (float(np.sign(linear)), float(np.sign(angular)))
        zones = self.settings.zones
        if motion == self._stopped_motion:
            zones = replace(zones, stop_m=zones.stop_m + STOP_HYSTERESIS_M)
        decision = apply_zones(
            linear,
            angular,
            points,
            self.footprint,
            zones,
            margin_m=margin,
        )
        if decision.stopped:
            self._stopped_motion = motion
        elif motion != (0.0, 0.0):
            self._stopped_motion = None  # moving freely (this way or another): released
        text = decision.message() or ZONES_CLEAR
        return ZoneState(decision, True, overridden, text)

    # ---- assisted modes --------------------------------------------------------------------

    @property
    def assist_kind(self) -> str | None:
        """'linear', 'path' or None."""
        with self._lock:
            return None if self._assist is None else self._assist.kind

    @property
    def assist_external(self) -> bool:
        """Whether the running mode was started by a planner (ROS /follow_path)."""
        with self._lock:
            return self._assist is not None and self._assist_external

    def planned_path(self) -> Points:
        """(N, 2) the path a path mode follows, or the shuttle's two points; empty if none."""
        with self._lock:
            assist = self._assist
            if isinstance(assist, PathFollower):
                return assist.trajectory.points()
            if isinstance(assist, LinearShuttle):
                return np.array(assist.points, dtype=np.float64)
            return np.zeros((0, 2))

    def assist_progress(self) -> float | None:
        """How far a path mode is (0-1); None for none or the shuttle."""
        with self._lock:
            return self._assist.progress if isinstance(self._assist, PathFollower) else None

    def start_shuttle(
        self,
        start_xy: tuple[float, float],
        stop_xy: tuple[float, float],
        *,
        max_linear_m_s: float,
        cycles: int | None = None,
    ) -> None:
        """The linear mode between two points (AssistError if it cannot start)."""
        with self._lock:
            minimum = self.profile.channels[self.drive[0]].min_speed if self.drive else 0.0
            pose = self.odometry.estimate(self.clock()).pose
            self._assist = LinearShuttle(
                start_xy,
                stop_xy,
                pose,
                self.settings.assist,
                max_linear_m_s=max_linear_m_s,
                min_linear_m_s=minimum,
                cycles=cycles,
            )
            self._assist_external = False
            self.revision += 1

    def start_path(
        self, waypoints: Sequence[tuple[float, float]], *, external: bool = False
    ) -> None:
        """The path mode through waypoints from where the robot is now."""
        with self._lock:
            pose = self.odometry.estimate(self.clock()).pose
            points = [(pose.x_m, pose.y_m), *waypoints]
            try:
                trajectory = along_path(np.array(points), self.settings.assist.cruise_m_s)
            except ValueError as err:
                raise AssistError(str(err)) from err
            self.start_trajectory(trajectory, external=external)

    def start_trajectory(self, trajectory: Trajectory, *, external: bool = False) -> None:
        """The path mode along a timed reference (the ellipse of eq. 6.1, a ROS path)."""
        with self._lock:
            self._assist = PathFollower(trajectory, self.settings.assist, self.clock())
            self._assist_external = external
            self.revision += 1

    def stop_assist(self, reason: str = "") -> bool:
        """End the running mode; True if one ran."""
        del reason
        with self._lock:
            running = self._assist is not None
            self._assist = None
            self._assist_external = False
            if running:
                self.revision += 1
            return running

    def assist_step(
        self, now: float | None = None, *, link_ok: bool = True
    ) -> AssistCommand | None:
        """What the running mode commands now; None when none runs.

        A done command ends the mode; so do a lost link and stale odometry (with a message).
        """
        with self._lock:
            assist = self._assist
            if assist is None:
                return None
            now = self.clock() if now is None else now
            if not link_ok:
                self.stop_assist()
                return AssistCommand(done=True, message=f"{assist.kind} mode stopped: LINK LOST")
            estimate = self.odometry.estimate(now)
            if estimate.stale:
                self.stop_assist()
                age = estimate.measured_age_s
                since = "no measurement yet" if age is None else f"nothing measured for {age:.1f} s"
                return AssistCommand(
                    done=True, message=f"{assist.kind} mode stopped: odometry stale ({since})"
                )
            # The pose when a command sent now lands, and the reference for that moment: the
            # link delay is taken out of the loop (a Smith predictor, as for the joints).
            pose = self.odometry.predict(now, self._one_way_s)
            command = assist.step(pose, now + self._one_way_s)
            if command.done:
                self.stop_assist()
            return command
