"""Driving with a map, a part of the console model: the drive pair composed from whichever
source commands it and passed through the safety zones last, the zones' override, the
operator's waypoints and shuttle points, the odometry reset, and the assisted modes (linear
shuttle, path following, seed 002's ellipse): one more automatic source, `Source.ASSIST`, run
from `update()`, yielding to any operator input, an e-stop, a halt, LINK LOST and stale
odometry."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

from ocu.console.channels import ChannelCommand, Source
from ocu.console.part import ModelPart
from ocu.control.drive import DriveBounds, scale_drive
from ocu.nav.assist import AssistError
from ocu.nav.navigator import ZoneState
from ocu.nav.tracking import ellipse
from ocu.records import CommandError, LinkState


class Driving(ModelPart):
    """The drive pair through the zones, waypoints and the assisted modes (`nav` does the
    navigation; ocu.nav.navigator)."""

    # ---- driving with a map ----------------------------------------------------------------

    @property
    def waypoints(self) -> tuple[tuple[float, float], ...]:
        """The operator's waypoints (odometry frame, m) for the path mode."""
        return self._waypoints

    def set_waypoints(self, points: Sequence[tuple[float, float]]) -> None:
        """Replace the waypoints (the map's clicks)."""
        checked = tuple((float(x), float(y)) for x, y in points)
        if not all(math.isfinite(v) for point in checked for v in point):
            raise CommandError("waypoints must be finite numbers")
        self._waypoints = checked
        self.events.waypoints_changed.emit(checked)

    def add_waypoint(self, x_m: float, y_m: float) -> None:
        """One more waypoint at the end."""
        self.set_waypoints((*self._waypoints, (x_m, y_m)))

    @property
    def shuttle_points(self) -> tuple[tuple[float, float], ...]:
        """The linear mode's two points (fewer while the operator marks them)."""
        return self._shuttle

    def add_shuttle_point(self, x_m: float, y_m: float) -> None:
        """Mark a point for the linear mode; the last two marked count."""
        if not (math.isfinite(x_m) and math.isfinite(y_m)):
            raise CommandError("a shuttle point must be finite")
        self._shuttle = (*self._shuttle, (float(x_m), float(y_m)))[-2:]
        self.events.shuttle_points_changed.emit(self._shuttle)

    def clear_waypoints(self) -> None:
        """No waypoints nor shuttle points; a running mode stops."""
        self.set_waypoints(())
        self._shuttle = ()
        self.events.shuttle_points_changed.emit(())
        self._end_assist("path cleared")
        self._publish()

    def reset_odometry(self) -> None:
        """The operator's odometry reset: the robot is at the origin again, sure of it."""
        self._end_assist("odometry reset")
        self.nav.reset_odometry()
        self.set_waypoints(())
        self._shuttle = ()
        self.events.shuttle_points_changed.emit(())
        self.events.odometry_reset.emit()
        self.events.message.emit("odometry reset: pose (0, 0, 0°)")

    def override_zones(self) -> None:
        """The deliberate override: the next motion passes the safety zones (pushing a box)."""
        self.nav.override_zones()
        self.events.message.emit(
            "safety zones OVERRIDDEN for the next motion (it ends when the tracks stop)"
        )
        self._apply_drive_now()
        self._emit_zones(self.nav.zones, force=True)

    @property
    def assist_mode(self) -> str | None:
        """The assisted mode running: 'linear', 'path' or None."""
        return self.nav.assist_kind

    def start_linear(
        self,
        start_xy: tuple[float, float] | None = None,
        stop_xy: tuple[float, float] | None = None,
        cycles: int | None = None,
    ) -> None:
        """The linear shuttle between two points (seed 002, Algorithm 5.4), the marked ones
        by default; CommandError if it cannot start."""
        if start_xy is None or stop_xy is None:
            if len(self._shuttle) < 2:
                raise CommandError("linear mode: mark two points on the map first")
            start_xy, stop_xy = self._shuttle
        self._start_assist(
            lambda: self.nav.start_shuttle(
                start_xy, stop_xy, max_linear_m_s=self._max_linear(), cycles=cycles
            ),
            f"linear mode: shuttling between ({start_xy[0]:.2f}, {start_xy[1]:.2f}) and "
            f"({stop_xy[0]:.2f}, {stop_xy[1]:.2f})",
        )

    def start_path(
        self, waypoints: Sequence[tuple[float, float]] | None = None, *, external: bool = False
    ) -> None:
        """Follow waypoints (the operator's when None) with Samson's controller."""
        points = tuple(self._waypoints if waypoints is None else waypoints)
        if not points:
            raise CommandError("no waypoints: click on the map to set some")
        self._start_assist(
            lambda: self.nav.start_path(points, external=external),
            f"path mode: following {len(points)} waypoint(s)",
            external=external,
        )

    def start_ellipse(self) -> None:
        """Seed 002's test: the ellipse of eq. 6.1 (40 s ideal) from where the robot is."""
        pose = self.nav.estimate().pose
        self._start_assist(
            lambda: self.nav.start_trajectory(ellipse(pose)),
            "path mode: the ellipse of seed 002 (3.6 m x 2 m, 40 s)",
        )

    def stop_assist(self, reason: str = "operator") -> None:
        """End the assisted mode; its channels stop."""
        self._end_assist(reason)
        self._publish()

    def _start_assist(
        self, start: Callable[[], None], message: str, *, external: bool = False
    ) -> None:
        if self._drive is None:
            raise CommandError("the profile has no chassis to drive")
        if not external:
            # Starting a mode is the operator's act: it takes over from ROS, ends an e-stop.
            self._operator_acted()
        for channel in self._drive:
            self._take_manual(channel)
        try:
            start()
        except AssistError as err:
            raise CommandError(str(err)) from err
        self.events.assist_changed.emit(self.nav.assist_kind, message)
        self.events.message.emit(message)

    def _end_assist(self, reason: str) -> bool:
        kind = self.nav.assist_kind
        if not self.nav.stop_assist(reason):
            self._zero_assist()
            return False
        self._zero_assist()
        text = f"{kind} mode stopped: {reason}"
        self.events.assist_changed.emit(None, text)
        self.events.message.emit(text)
        return True

    def _zero_assist(self) -> None:
        for channel in self._drive or ():
            if self._requested(channel).source is Source.ASSIST:
                self._set_channel(channel, 0.0, Source.NONE)

    def _max_linear(self) -> float:
        assert self._drive is not None
        return self.limits.get(self._drive[0])

    def _assist_tick(self, now: float) -> None:
        link_ok = self.robot.link_state is LinkState.CONNECTED
        command = self.nav.assist_step(now, link_ok=link_ok)
        if command is None or self._drive is None:
            return
        if command.done:
            self._zero_assist()
            self.events.assist_changed.emit(None, command.message)
            self.events.message.emit(command.message)
            return
        linear_name, turn_name = self._drive
        for name, value in ((linear_name, command.linear_m_s), (turn_name, command.angular_rad_s)):
            # A channel the operator holds stays the operator's.
            if self.mux.may_take(Source.ASSIST.value, self._requested(name).source.value):
                self._drive_request[name] = ChannelCommand(
                    float(value), Source.ASSIST if value else Source.NONE
                )
        self._apply_drive()

    def _apply_drive(self) -> None:
        """Both drive channels from the operator's request, scaled by one factor."""
        assert self._drive is not None
        linear_name, turn_name = self._drive
        linear, turn = self._drive_request[linear_name], self._drive_request[turn_name]
        channels = self.profile.channels
        bounds = DriveBounds(
            max_linear_m_s=self.limits.get(linear_name),
            max_angular_rad_s=self.limits.get(turn_name),
            min_linear_m_s=channels[linear_name].min_speed,
            min_angular_rad_s=channels[turn_name].min_speed,
        )
        v, w = scale_drive(linear.velocity, turn.velocity, bounds)
        # The safety zones come last, whoever commands: keys, sliders, ROS, assisted modes.
        zones = self.nav.guard(v, w)
        if zones.decision is not None:
            v, w = zones.decision.linear_m_s, zones.decision.angular_rad_s
        self._emit_zones(zones)
        self._store(linear_name, ChannelCommand(v, linear.source if v else Source.NONE))
        self._store(turn_name, ChannelCommand(w, turn.source if w else Source.NONE))

    def _apply_drive_now(self) -> None:
        """Compose the drive pair again (a new scan, a tick) if it is asked to move."""
        if self._drive is None:
            return
        if any(self._drive_request[name].velocity for name in self._drive) or any(
            self._channels[name].velocity for name in self._drive
        ):
            self._apply_drive()
            self._publish()
        else:
            self._emit_zones(self.nav.guard(0.0, 0.0))

    def _emit_zones(self, zones: ZoneState, *, force: bool = False) -> None:
        if zones.text != self._zone_text or force:
            self._zone_text = zones.text
            self.events.zones_changed.emit(zones)
        limiting = zones.limiting
        if limiting and not self._zone_limiting:
            self.events.message.emit(zones.text)
        self._zone_limiting = limiting
