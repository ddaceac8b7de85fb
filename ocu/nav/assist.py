"""Seed 002's assisted modes as pure state machines: the linear shuttle and path following.

Each `step(pose, now)` gets the pose the robot will have when the command lands (odometry
predicted one link delay ahead) and returns the speeds to command, or says it is done. The
caller owns the rules around them: any operator input ends a mode at once, and so do an
emergency stop, LINK LOST and stale odometry (ocu.nav.navigator, ocu.console.model).

- `LinearShuttle` (Algorithm 5.4): back and forth between two points along the line through
  them, v = sqrt(|x_ref - x| * gain) (eq. 5.5, in metres: gain 0.05 m/s² is the thesis' 50
  in millimetres), turning round at each end; ω = 0.
- `PathFollower` (Algorithms 5.2-5.3): Samson's controller on a timed reference (an ellipse,
  waypoints, a path from ROS). The reference clock waits while the robot is more than
  `max_lag_m` behind it (Algorithm 5.2 generates the next target only once the robot is
  there), so a stall or a lossy link does not leave the robot chasing a reference far ahead.
  It is done when the reference has ended and the robot is within `goal_tolerance_m` of its
  end, or gives up `SETTLE_S` after the reference ended.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ocu.nav.geometry import Pose, relative
from ocu.nav.tracking import Trajectory, samson, tracking_error
from ocu.profile import AssistSettings

SHUTTLE = "linear"
PATH = "path"
# After the reference ended, the robot has this long to reach its end.
SETTLE_S = 6.0
# The shuttle refuses to start when the robot faces more than this away from the line.
SHUTTLE_ALIGNMENT_RAD = math.radians(20.0)


@dataclass(frozen=True)
class AssistCommand:
    """What a mode asks for now; `done` with a message when it has finished."""

    linear_m_s: float = 0.0
    angular_rad_s: float = 0.0
    done: bool = False
    message: str = ""


class AssistError(ValueError):
    """A mode that cannot start as asked (points too close, robot facing away)."""


class LinearShuttle:
    """Back and forth between `start` and `stop` along the line through them (Algorithm 5.4)."""

    kind = SHUTTLE

    def __init__(
        self,
        start_xy: tuple[float, float],
        stop_xy: tuple[float, float],
        pose: Pose,
        settings: AssistSettings,
        *,
        max_linear_m_s: float,
        min_linear_m_s: float,
        cycles: int | None = None,
    ) -> None:
        length = math.dist(start_xy, stop_xy)
        if length < 0.2:
            raise AssistError(f"the two points are {length:.2f} m apart; at least 0.2 m")
        self.axis = Pose(
            start_xy[0], start_xy[1], math.atan2(stop_xy[1] - start_xy[1], stop_xy[0] - start_xy[0])
        )
        self.length_m = length
        off = abs(math.remainder(pose.heading_rad - self.axis.heading_rad, math.pi))
        if off > SHUTTLE_ALIGNMENT_RAD:
            raise AssistError(
                f"the robot faces {math.degrees(off):.0f}° away from the line between the "
                "points: turn it along the line first"
            )
        self.settings = settings
        self.max_linear_m_s = max_linear_m_s
        self.min_linear_m_s = min_linear_m_s
        self.cycles = cycles
        self.turns = 0
        # Forward along the line when facing the stop point, else in reverse.
        self.facing = (
            1.0
            if abs(math.remainder(pose.heading_rad - self.axis.heading_rad, math.tau)) < math.pi / 2
            else -1.0
        )
        self.direction = 1.0
        self.points = (start_xy, stop_xy)

    def position(self, pose: Pose) -> float:
        """Where the robot is along the line (0 at the start point)."""
        return relative(self.axis, pose).x_m

    def step(self, pose: Pose, now_s: float) -> AssistCommand:
        """Eq. 5.5 toward the end it is heading for; turn round past it."""
        del now_s
        x = self.position(pose)
        if x <= 0.0 and self.direction < 0:
            self.direction = 1.0
            self.turns += 1
        elif x >= self.length_m and self.direction > 0:
            self.direction = -1.0
            self.turns += 1
        if self.cycles is not None and self.turns >= 2 * self.cycles:
            return AssistCommand(done=True, message=f"linear: {self.cycles} shuttles done")
        target = self.length_m if self.direction > 0 else 0.0
        speed = math.sqrt(abs(target - x) * self.settings.linear_gain_m_per_s2)
        speed = min(max(speed, self.min_linear_m_s), self.max_linear_m_s)
        # Along the line in robot terms: forward if the robot faces the way it must go.
        return AssistCommand(self.direction * self.facing * speed, 0.0)


class PathFollower:
    """Samson's controller along a trajectory whose clock waits for the robot (see above)."""

    kind = PATH

    def __init__(self, trajectory: Trajectory, settings: AssistSettings, now_s: float) -> None:
        self.trajectory = trajectory
        self.settings = settings
        self.started_s = now_s
        self._last_s = now_s
        self.reference_s = 0.0
        self.waited_s = 0.0

    @property
    def progress(self) -> float:
        """Fraction of the reference's time done (0-1)."""
        duration = self.trajectory.duration_s
        return 1.0 if duration <= 0.0 else min(self.reference_s / duration, 1.0)

    def step(self, pose: Pose, now_s: float) -> AssistCommand:
        """Samson's (v, ω) for the reference now; done at the end."""
        dt = max(now_s - self._last_s, 0.0)
        self._last_s = now_s
        reference = self.trajectory.at(self.reference_s)
        error = tracking_error(pose, reference)
        # Algorithm 5.2: the reference goes on only while the robot keeps up with it.
        if error.x_m > self.settings.max_lag_m and self.reference_s < self.trajectory.duration_s:
            self.waited_s += dt
        else:
            self.reference_s += dt
        end = self.trajectory.end
        ended = self.reference_s >= self.trajectory.duration_s
        distance = math.hypot(end.x_m - pose.x_m, end.y_m - pose.y_m)
        if ended and distance <= self.settings.goal_tolerance_m:
            return AssistCommand(
                done=True,
                message=f"path done in {now_s - self.started_s:.1f} s, "
                f"{distance * 100:.0f} cm from its end",
            )
        if ended and self.reference_s - self.trajectory.duration_s > SETTLE_S:
            return AssistCommand(
                done=True,
                message=f"path ended {distance:.2f} m from its end (not reached in "
                f"{SETTLE_S:.0f} s)",
            )
        reference = self.trajectory.at(self.reference_s)
        if ended:
            # At rest at the end Samson's k2 vanishes: head for the end point instead.
            local = relative(pose, end.pose)
            heading_error = math.atan2(local.y_m, local.x_m)
            linear = self.settings.cruise_m_s * 0.5 * math.copysign(1.0, local.x_m)
            if abs(heading_error) > math.pi / 2:
                heading_error = math.remainder(heading_error + math.pi, math.tau)
            return AssistCommand(linear * min(1.0, distance / 0.3), 2.0 * heading_error)
        linear, angular = samson(pose, reference, self.settings.samson_b, self.settings.samson_xi)
        return AssistCommand(linear, angular)
