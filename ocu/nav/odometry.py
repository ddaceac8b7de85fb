"""Odometry on the OCU: dead reckoning from the tracks' speeds, or the commands, and the IMU.

The Engineer's tracks report a speed but no position (seed 000 §3.1), so the pose is the
integral of the chassis' speeds. What the robot does is known in three ways, each late:

- **commands** the OCU sent act one link delay (half the measured round trip) after they
  left, if the servos start at all (the pair moves once one speed reaches its `min_speed`),
  and stop by the robot's own watchdog when no command arrived for `robot_watchdog_s`;
- **track speeds** in telemetry were measured half a round trip before they arrived: from
  that moment until the next command took effect the robot moved at them (a stall against
  a wall, a deadband, a watchdog stop — all show here);
- **the IMU heading** of the protocol extension (status version 2), when the robot has one:
  the heading is then measured, not integrated.

The estimate is event-sourced: velocity segments, each from the moment a command acted or a
measurement applied, integrated from an anchor pose that older segments are folded into. A
measurement rewrites the segments since it was taken, so the pose stays the best integral
of everything known. The uncertainty grows with the distance and the angle travelled (a 3x3
covariance propagated along the arcs; more for commanded than for measured speeds) and an
IMU heading bounds it. Pure: no clock of its own, no Qt.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ocu.nav.geometry import ORIGIN, Pose, advance, wrap
from ocu.profile import OdometrySettings

Matrix = npt.NDArray[np.float64]

FROM_COMMANDS = "commands"
FROM_TRACKS = "tracks"
STOPPED = "stopped"
# Older segments than this are folded into the anchor: a measurement never arrives later.
HISTORY_S = 5.0
# At most this many segments are kept (a robot flooding telemetry cannot grow the list).
MAX_SEGMENTS = 400
# Step of the covariance propagation along long arcs.
COVARIANCE_STEP_S = 0.1


@dataclass
class _Segment:
    """From `start_s` on the robot moved at (linear, angular), as `source` says."""

    start_s: float
    linear_m_s: float
    angular_rad_s: float
    source: str
    # A measured heading at start_s (the IMU), None when the heading is integrated.
    heading_rad: float | None = None
    # Whether the robot changed speed here by itself (a command acted, its watchdog fired),
    # as opposed to a segment split for a measurement.
    command_start: bool = False


@dataclass(frozen=True)
class OdometryEstimate:
    """The pose now with its uncertainty, how it is known, and the speeds in force."""

    pose: Pose
    covariance: Matrix
    linear_m_s: float
    angular_rad_s: float
    source: str
    heading_measured: bool
    stale: bool
    measured_age_s: float | None
    distance_m: float

    @property
    def sigma_xy_m(self) -> float:
        """The larger standard deviation of the position (the ellipse's half major axis)."""
        return float(math.sqrt(max(np.linalg.eigvalsh(self.covariance[:2, :2]).max(), 0.0)))

    @property
    def sigma_heading_rad(self) -> float:
        """Standard deviation of the heading."""
        return float(math.sqrt(max(self.covariance[2, 2], 0.0)))


# A complete segment as it was integrated: start, end, speeds, source and heading fix.
_SegmentKey = tuple[float, float, float, float, str, float | None]


def _key(segment: _Segment, end_s: float) -> _SegmentKey:
    return (
        segment.start_s,
        end_s,
        segment.linear_m_s,
        segment.angular_rad_s,
        segment.source,
        segment.heading_rad,
    )


class Odometry:
    """Dead reckoning of one chassis (see the module docstring); call from one thread."""

    def __init__(
        self,
        track_width_m: float,
        settings: OdometrySettings,
        *,
        min_linear_m_s: float = 0.0,
        min_angular_rad_s: float = 0.0,
        watchdog_s: float = 1.0,
        now_s: float = 0.0,
    ) -> None:
        self.track_width_m = track_width_m
        self.settings = settings
        self.min_linear_m_s = min_linear_m_s
        self.min_angular_rad_s = min_angular_rad_s
        self.watchdog_s = watchdog_s
        self.one_way_s = 0.0
        # Robot seconds per second of the clock the events come with: a replay played at 4x
        # delivers four seconds of the robot's motion in one.
        self.time_scale = 1.0
        self.reset(now_s)

    # ---- inputs ------------------------------------------------------------------------

    def reset(self, now_s: float, pose: Pose = ORIGIN) -> None:
        """Start again at `pose` with no uncertainty (the operator's reset)."""
        self._anchor_s = now_s
        self._anchor = pose
        self._anchor_cov = np.zeros((3, 3))
        self._anchor_distance_m = 0.0
        self._segments: list[_Segment] = [_Segment(now_s, 0.0, 0.0, STOPPED)]
        self._commanded = (0.0, 0.0)
        self._last_sent_s: float | None = None
        self._measured_at_s: float | None = None
        self._heading_measured = False
        # The IMU's heading that the reset pose's heading stands for.
        self._yaw_offset_rad: float | None = None
        self._last_yaw_rad: float | None = None
        self._reset_yaw_pending = True
        # The state after each complete segment, with the segment's key: estimates at 20-50 Hz
        # integrate only what changed since (a 5 s history is ~50 segments at 10 Hz).
        self._cache: list[tuple[_SegmentKey, Pose, Matrix, float]] = []
        self._cache_time_scale = self.time_scale

    def set_round_trip(self, round_trip_s: float | None) -> None:
        """The link's measured round trip: commands act half of it after they were sent."""
        if round_trip_s is not None and math.isfinite(round_trip_s) and round_trip_s >= 0.0:
            self.one_way_s = round_trip_s / 2.0

    def on_command(self, sent_s: float, linear_m_s: float, angular_rad_s: float) -> None:
        """A command went on the wire at `sent_s` (repeats feed the robot's watchdog)."""
        self._last_sent_s = sent_s
        moving = self._deadband(linear_m_s, angular_rad_s)
        acts_s = sent_s + self.one_way_s
        if moving == self._commanded and self._segments[-1].source != STOPPED:
            return
        if moving == self._commanded and moving == (0.0, 0.0):
            return
        self._commanded = moving
        source = FROM_COMMANDS if moving != (0.0, 0.0) else STOPPED
        self._add(_Segment(acts_s, moving[0], moving[1], source))

    def on_tracks(self, received_s: float, left_m_s: float, right_m_s: float) -> None:
        """Track belt speeds measured half a round trip before they arrived."""
        linear = (left_m_s + right_m_s) / 2.0
        angular = (right_m_s - left_m_s) / self.track_width_m
        taken_s = max(received_s - self.one_way_s, self._anchor_s)
        self._measured_at_s = received_s
        self._fold(received_s)
        index = self._split(taken_s)
        # From the reading until the next command acted, the robot moved as measured.
        end = index + 1
        while end < len(self._segments) and not self._segments[end].command_start:
            end += 1
        for segment in self._segments[index:end]:
            segment.linear_m_s, segment.angular_rad_s = linear, angular
            segment.source = FROM_TRACKS if (linear or angular) else STOPPED

    def on_heading(self, received_s: float, yaw_rad: float) -> None:
        """The IMU's heading, taken half a round trip before it arrived."""
        self._measured_at_s = received_s
        self._last_yaw_rad = yaw_rad
        if self._yaw_offset_rad is None or self._reset_yaw_pending:
            # The first heading after a reset defines the IMU's zero in our frame.
            self._yaw_offset_rad = wrap(yaw_rad - self.estimate(received_s).pose.heading_rad)
            self._reset_yaw_pending = False
        self._heading_measured = True
        taken_s = max(received_s - self.one_way_s, self._anchor_s)
        self._fold(received_s)
        index = self._split(taken_s)
        self._segments[index].heading_rad = wrap(yaw_rad - self._yaw_offset_rad)

    # ---- the estimate ------------------------------------------------------------------

    def estimate(self, now_s: float) -> OdometryEstimate:
        """The pose at `now_s` (robot time = OCU time; commands act after the delay)."""
        self._watchdog(now_s)
        pose, cov, distance, segment = self._integrate(now_s)
        age = None if self._measured_at_s is None else now_s - self._measured_at_s
        stale = age is None or age > self.settings.stale_after_s
        return OdometryEstimate(
            pose=pose,
            covariance=cov,
            linear_m_s=segment.linear_m_s,
            angular_rad_s=segment.angular_rad_s,
            source=segment.source,
            heading_measured=self._heading_measured,
            stale=stale,
            measured_age_s=age,
            distance_m=distance,
        )

    def predict(self, now_s: float, ahead_s: float) -> Pose:
        """Where the robot will be `ahead_s` after now, by the commands already sent."""
        return self.estimate(now_s + max(ahead_s, 0.0)).pose

    # ---- internals ---------------------------------------------------------------------

    def _deadband(self, linear: float, angular: float) -> tuple[float, float]:
        # The servos start only when one of the pair reaches its starting speed.
        if abs(linear) >= self.min_linear_m_s or abs(angular) >= self.min_angular_rad_s:
            return float(linear), float(angular)
        return 0.0, 0.0

    def _watchdog(self, now_s: float) -> None:
        if self._last_sent_s is None or self._commanded == (0.0, 0.0):
            return
        stop_s = self._last_sent_s + self.one_way_s + self.watchdog_s / self.time_scale
        if stop_s < now_s:
            self._commanded = (0.0, 0.0)
            self._add(_Segment(stop_s, 0.0, 0.0, STOPPED))

    def _add(self, segment: _Segment) -> None:
        """The robot changes speed at segment.start_s: everything after follows it."""
        index = self._split(max(segment.start_s, self._anchor_s))
        self._segments[index].command_start = True
        for later in self._segments[index:]:
            later.linear_m_s, later.angular_rad_s = segment.linear_m_s, segment.angular_rad_s
            later.source = segment.source
        if len(self._segments) > MAX_SEGMENTS:
            self._fold_before(self._segments[len(self._segments) // 2].start_s)

    def _split(self, at_s: float) -> int:
        """Index of a segment starting exactly at `at_s` (made by splitting if needed)."""
        segments = self._segments
        index = 0
        for k in range(len(segments) - 1, -1, -1):
            if segments[k].start_s <= at_s:
                index = k
                break
        current = segments[index]
        if current.start_s == at_s:
            return index
        copy = _Segment(at_s, current.linear_m_s, current.angular_rad_s, current.source)
        segments.insert(index + 1, copy)
        return index + 1

    def _fold(self, now_s: float) -> None:
        """Fold segments that ended more than HISTORY_S ago into the anchor."""
        self._fold_before(now_s - HISTORY_S)

    def _fold_before(self, horizon_s: float) -> None:
        self._check_cache()
        while len(self._segments) > 1 and self._segments[1].start_s <= horizon_s:
            first, second = self._segments[0], self._segments[1]
            key = _key(first, second.start_s)
            if self._cache and self._cache[0][0] == key:
                # The estimate integrated this segment already, from this very anchor.
                _key_was, pose, cov, distance = self._cache.pop(0)
            else:
                self._cache.clear()
                pose, cov, distance = self._anchor, self._anchor_cov, self._anchor_distance_m
                if first.heading_rad is not None:
                    pose, cov = self._fix_heading(pose, cov, first.heading_rad)
                dt_s = second.start_s - first.start_s
                pose, cov, distance = self._step(pose, cov, distance, first, dt_s)
            self._anchor, self._anchor_cov, self._anchor_distance_m = pose, cov, distance
            self._anchor_s = second.start_s
            self._segments.pop(0)

    def _check_cache(self) -> None:
        if self.time_scale != self._cache_time_scale:
            self._cache.clear()
            self._cache_time_scale = self.time_scale

    def _integrate(self, now_s: float) -> tuple[Pose, Matrix, float, _Segment]:
        self._check_cache()
        pose, cov, distance = self._anchor, self._anchor_cov, self._anchor_distance_m
        segments, cache = self._segments, self._cache
        last = segments[0]
        for k, segment in enumerate(segments):
            if segment.start_s > now_s:
                break
            last = segment
            next_s = segments[k + 1].start_s if k + 1 < len(segments) else math.inf
            complete = next_s <= now_s
            if complete:
                key = _key(segment, next_s)
                if k < len(cache) and cache[k][0] == key:
                    _key_was, pose, cov, distance = cache[k]
                    continue
                del cache[k:]
            if segment.heading_rad is not None:
                pose, cov = self._fix_heading(pose, cov, segment.heading_rad)
            end_s = min(next_s, now_s)
            pose, cov, distance = self._step(pose, cov, distance, segment, end_s - segment.start_s)
            if complete:
                cache.append((key, pose, cov, distance))
        return pose, cov.copy(), distance, last

    def _fix_heading(self, pose: Pose, cov: Matrix, heading_rad: float) -> tuple[Pose, Matrix]:
        sigma2 = self.settings.imu_heading_sigma_rad**2
        cov = cov.copy()
        if cov[2, 2] > sigma2:
            # Conditioning on the heading: its variance drops, cross terms with it shrink.
            ratio = math.sqrt(sigma2 / cov[2, 2])
            cov[:2, 2] *= ratio
            cov[2, :2] *= ratio
            cov[2, 2] = sigma2
        return Pose(pose.x_m, pose.y_m, heading_rad), cov

    def _step(
        self, pose: Pose, cov: Matrix, distance: float, segment: _Segment, dt_s: float
    ) -> tuple[Pose, Matrix, float]:
        dt_s *= self.time_scale
        if dt_s <= 0.0 or (segment.linear_m_s == 0.0 and segment.angular_rad_s == 0.0):
            return pose, cov, distance
        settings = self.settings
        factor = settings.commanded_noise_factor if segment.source == FROM_COMMANDS else 1.0
        steps = max(1, math.ceil(dt_s / COVARIANCE_STEP_S))
        h = dt_s / steps
        # P' = J P Jᵀ + B N Bᵀ, J = [[1, 0, a], [0, 1, b], [0, 0, 1]], B = [[c, 0], [s, 0], [0, 1]],
        # N = diag(n1, n2), written out on floats (numpy costs more than the arithmetic at 3x3).
        p00, p01, p02 = float(cov[0, 0]), float(cov[0, 1]), float(cov[0, 2])
        p11, p12, p22 = float(cov[1, 1]), float(cov[1, 2]), float(cov[2, 2])
        for _ in range(steps):
            ds = segment.linear_m_s * h
            dtheta = segment.angular_rad_s * h
            mid = pose.heading_rad + dtheta / 2.0
            c, s = math.cos(mid), math.sin(mid)
            a, b = -ds * s, ds * c
            n1 = factor * settings.linear_noise_m2_per_m * abs(ds)
            n2 = factor * (
                settings.heading_noise_rad2_per_rad * abs(dtheta)
                + settings.heading_drift_rad2_per_m * abs(ds)
            )
            p00, p01, p02, p11, p12 = (
                p00 + 2.0 * a * p02 + a * a * p22 + c * c * n1,
                p01 + a * p12 + b * (p02 + a * p22) + c * s * n1,
                p02 + a * p22,
                p11 + 2.0 * b * p12 + b * b * p22 + s * s * n1,
                p12 + b * p22,
            )
            p22 = p22 + n2
            pose = advance(pose, ds, dtheta)
            distance += abs(ds)
        cov = np.array([[p00, p01, p02], [p01, p11, p12], [p02, p12, p22]])
        return pose, cov, distance
