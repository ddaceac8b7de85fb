"""Step 3, the axis map: each RCP axis pulsed in turn; which motor answers, with which sign."""

from __future__ import annotations

from collections.abc import Iterable, Sequence

from ocu.calibrate.core import (
    MAX_SCANS,
    NEGATIVE,
    POSITIVE,
    ROUGH_FIT_ERROR,
    CalibratorCore,
    Measured,
    _Joint,
    _RescanError,
    _Response,
    _unknown_motor,
    log,
)
from ocu.calibrate.fit import FitError, fit_ticks_per_rad
from ocu.calibrate.guard import (
    CalibrationAbortedError,
)
from ocu.calibrate.observer import Sample
from ocu.calibrate.probe import MISMATCH, NOTE
from ocu.calibrate.raw import tick_delta
from ocu.profile import AXIS_COUNT, Motor


class AxisScan(CalibratorCore):
    """Step 3, the axis map: each RCP axis pulsed in turn; which motor answers, with which sign."""

    # ---- axis map ------------------------------------------------------------------------

    def _scan(self) -> None:
        """Pulse each axis in turn; map the channels from the motors that answer."""
        for attempt in range(MAX_SCANS):
            try:
                self._scan_axes()
                return
            except _RescanError as err:
                if attempt == MAX_SCANS - 1:
                    raise CalibrationAbortedError(
                        f"the round trip kept growing ({err.margin_s:.2f} s after "
                        f"{MAX_SCANS} scans): check the link with `ocu probe`"
                    ) from err
                self.operator.say(
                    f"the robot answers slowly (round trip up to {err.margin_s:.2f} s): "
                    "scanning again with a longer wait"
                )
                self._forget_scan()

    def _forget_scan(self) -> None:
        """Drop what a scan judged with too short a wait."""
        self._axis_map.clear()
        for key in [k for k in self.result.measured if k.startswith("channels.")]:
            del self.result.measured[key]
        # The findings of the axis scan (and of the devices the operator named in it).
        self.result.findings = [
            f for f in self.result.findings if not f.text.startswith(("axis ", "device "))
        ]
        for joint in self._joints.values():
            joint.channel = joint.axis = None
            joint.free.clear()
        self._round_trips.clear()

    def _scan_axes(self) -> None:
        silent = [axis for axis in range(AXIS_COUNT) if not self._scan_axis(axis)]
        missing = [name for name in self.profile.channels if name not in self._axis_map]
        if missing and silent:
            # A pulse can miss the robot (a burst of loss, a link that stalled): the axes
            # that seemed to drive nothing get a second pulse before a channel is given up.
            self.operator.say(
                f"no axis answered for {', '.join(missing)}: pulsing the silent axes again"
            )
            for axis in silent:
                self._scan_axis(axis)
        for name in self.profile.channels:
            if name not in self._axis_map:
                self._finding(
                    MISMATCH,
                    f"no axis moves the {name}: channels.{name}.axis stays an assumption",
                    f"channels.{name}.axis",
                )

    def _scan_axis(self, axis: int) -> bool:
        """Pulse one axis and map what answered; whether anything did."""
        responses = self._pulse(axis)
        moved = {d: r for d, r in responses.items() if r.direction() != 0}
        # Speeds and echoed commands are exact; a position alone may be noise when
        # another device answers by its speed.
        strong = {d for d, r in moved.items() if r.speed_raw or r.command_raw}
        if strong:
            moved = {d: moved[d] for d in strong}
        joints = [d for d in moved if d in self._joints]
        tracks = [d for d in moved if self._is_track(d)]
        others = [d for d in moved if d not in joints and d not in tracks]
        if not moved:
            self.operator.say(f"axis {axis}: nothing answers")
            return False
        if len(joints) == 1 and not tracks and not others:
            joint = self._identify(joints[0], moved[joints[0]])
            if joint is not None:
                self._map_joint(axis, joint, responses[joints[0]])
            return True
        if len(tracks) == 2 and not joints and not others:
            self._map_drive(axis, {d: moved[d] for d in tracks})
            return True
        log.info("axis %d: ambiguous responses %s", axis, moved)
        names = [self._name(d) for d in moved]
        self._finding(
            MISMATCH,
            f"axis {axis} moves several motors ({', '.join(names)}): not mapped",
        )
        return True

    def _pulse(self, axis: int) -> dict[int, _Response]:
        """Pulse an axis out and back (a third leg if the first direction was blocked);
        what each device did during the first leg."""
        value = self.config.scan_axis_value
        self._allowed = None
        before = self._settle()
        start = self.clock()
        margin = self._margin_s
        try:
            self._command({axis: value})

            def answered() -> bool:
                return any(s.received_at >= start + margin for s in self.log.samples(start))

            self.log.wait(answered, margin + 3 * self._period_s + 1.0, self._poll)
        finally:
            self._zero()
        duration = self.clock() - start
        after = self._settle()
        during = self.log.samples(start)
        first = self._responses(before, after, during)
        self._learn_round_trip(start, during)
        joints = [d for d, r in first.items() if d in self._joints and r.direction()]
        moved_tracks = [d for d, r in first.items() if self._is_track(d) and r.speed_raw]
        if not joints and not moved_tracks:
            return first
        # Back the way it came; a joint that did not move (at a stop) moves away and back.
        back_start = self.clock()
        self._legs(axis, [(-value, duration)])
        after_back = self._settle()
        back = self._responses(after, after_back, self.log.samples(back_start))
        for device_id in joints:
            joint = self._joints[device_id]
            if first[device_id].moved_ticks or first[device_id].speed_raw:
                joint.free.add(first[device_id].direction())
            if back[device_id].moved_ticks or back[device_id].speed_raw:
                joint.free.add(back[device_id].direction())
            speeds = [r.speed_raw for r in (first[device_id], back[device_id]) if r.speed_raw]
            if speeds:
                joint.scan_speed_rad_s = max(abs(s) for s in speeds) / self.speed_scale
                if joint.rough_ticks_per_rad is None:
                    runs = self._runs(joint, self.log.samples(start))
                    try:
                        fit = fit_ticks_per_rad([run for run, _ in runs])
                    except FitError:
                        fit = None
                    # Short noisy runs may tell nothing: only a fit known to 15 % is used.
                    error = fit.relative_error if fit is not None else None
                    if fit is not None and error is not None and error <= ROUGH_FIT_ERROR:
                        joint.rough_ticks_per_rad = abs(fit.value)
            blocked_first = not first[device_id].moved_ticks and not first[device_id].speed_raw
            if blocked_first and (back[device_id].moved_ticks or back[device_id].speed_raw):
                self._legs(axis, [(value, duration)])
                self._settle()
        return first

    def _learn_round_trip(self, start: float, during: Sequence[Sample]) -> None:
        """The round trip from a pulse's first echo; the scan restarts if it was too slow."""
        noise = self.config.speed_noise_raw
        for sample in during:
            if any(
                abs(r.speed_command) > noise or abs(r.speed) > noise for r in sample.motors.values()
            ):
                self._round_trips.append(sample.received_at - start)
                break
        if not self._round_trips:
            return
        margin = max(self.config.min_margin_s, 1.5 * min(self._round_trips) + 0.05)
        if margin > self._margin_s:
            # The pulses so far were judged with too short a wait: a reply may have been
            # counted as the next axis's. Scan again with the longer wait.
            self._margin_s = margin
            raise _RescanError(margin)
        self._margin_s = margin

    def _responses(
        self, before: Sample, after: Sample, during: Iterable[Sample]
    ) -> dict[int, _Response]:
        noise = self.config.speed_noise_raw
        speed: dict[int, int] = {}
        command: dict[int, int] = {}
        for sample in during:
            for device_id, record in sample.motors.items():
                if abs(record.speed) > max(abs(speed.get(device_id, 0)), noise):
                    speed[device_id] = record.speed
                if abs(record.speed_command) > max(abs(command.get(device_id, 0)), noise):
                    command[device_id] = record.speed_command
        responses: dict[int, _Response] = {}
        for device_id in after.motors:
            moved = 0
            joint = self._joints.get(device_id)
            if joint is not None and device_id in before.motors:
                delta = tick_delta(
                    before.motors[device_id].position, after.motors[device_id].position
                )
                # Beyond three times the spread of the resting readings (and a few ticks):
                # a real move, not noise.
                moved = delta if abs(delta) > 3 * joint.noise_ticks + 3 else 0
            responses[device_id] = _Response(
                speed.get(device_id, 0), command.get(device_id, 0), moved
            )
        return responses

    def _is_track(self, device_id: int) -> bool:
        motor = self.profile.motor_by_device(device_id)
        return motor is not None and motor.track is not None

    def _name(self, device_id: int) -> str:
        motor = self.profile.motor_by_device(device_id)
        return f"device {device_id} ({motor.name})" if motor else f"device {device_id}"

    def _identify(self, device_id: int, response: _Response) -> _Joint | None:
        """The joint a device is: the profile's, unless the operator names another."""
        joint = self._joints[device_id]
        profile_motor = self.profile.motor_by_device(device_id)
        choices = [m.name for m in self.profile.motors.values() if m.has_position]
        answer = self.operator.identify_joint(
            device_id, profile_motor.name if profile_motor else None, choices
        )
        if answer is not None and (profile_motor is None or answer != profile_motor.name):
            motor = self.profile.motors[answer]
            self._finding(
                NOTE,
                f"device {device_id} is the {answer} (the operator saw it move), not the "
                f"{profile_motor.name if profile_motor else 'unknown device'} the profile says",
                f"motors.{answer}.device_id",
            )
            self._rename(joint, motor)
            self._measure(
                Measured(
                    f"motors.{answer}.device_id",
                    device_id,
                    f"guided: pulsing one axis moved device {device_id}, and the operator "
                    f"saw the {answer} move",
                )
            )
        elif joint.motor.name.startswith("device"):
            self._finding(
                MISMATCH,
                f"device {device_id} moves, but the profile has no motor with that ID",
                "motors.*.device_id",
            )
            return None
        return joint

    def _rename(self, joint: _Joint, motor: Motor) -> None:
        """The device is another motor than the profile says: its zero offset goes with it."""
        old = joint.motor.name
        if self._zero_owner.get(old) == joint.device_id:
            del self._zero_owner[old]
            del self.result.measured[f"motors.{old}.zero_offset_ticks"]
        # A device the profile gave this name to is not that motor (and is still unknown).
        for other in self._joints.values():
            if other is not joint and other.motor.name == motor.name:
                other.motor = _unknown_motor(other.device_id)
        joint.motor = motor
        self._record_zero(joint)

    def _map_joint(self, axis: int, joint: _Joint, response: _Response) -> None:
        channel = joint.motor.channel
        if channel is None:
            self._finding(
                NOTE, f"axis {axis} moves the {joint.motor.name}, which no channel drives"
            )
            return
        if channel in self._axis_map:
            self._finding(
                MISMATCH,
                f"axis {axis} also moves the {joint.motor.name} (already on axis "
                f"{self._axis_map[channel][0]}): not mapped",
            )
            return
        direction = response.direction()
        if direction == 0 and len(joint.free) == 1:
            # Blocked on the way out, and no echoed command: the way back, reversed.
            direction = -next(iter(joint.free))
        sign = POSITIVE if direction > 0 else NEGATIVE
        joint.channel, joint.axis, joint.sign = channel, axis, sign
        self._axis_map[channel] = (axis, sign)
        evidence = (
            "position"
            if response.moved_ticks
            else "speed"
            if response.speed_raw
            else "speed command"
        )
        self._record_axis(
            channel,
            axis,
            sign,
            f"a pulse of {self.config.scan_axis_value:+d} on axis {axis} moved the "
            f"{joint.motor.name} (device {joint.device_id}) {'up' if sign > 0 else 'down'} "
            f"the position scale ({evidence})",
        )

    def _map_drive(self, axis: int, tracks: dict[int, _Response]) -> None:
        sides: dict[str, int] = {}
        for device_id, response in tracks.items():
            motor = self.profile.motor_by_device(device_id)
            assert motor is not None
            assert motor.track is not None
            sides[motor.track] = response.direction()
        drive = self.profile.drive_channels
        if drive is None or set(sides) != {"left", "right"}:
            self._finding(MISMATCH, f"axis {axis} moves the tracks, but the profile has no drive")
            return
        linear, turn = drive
        if sides["left"] == sides["right"]:
            channel, sign = linear, sides["left"]
            how = "both tracks answered with one sign (drive: linear)"
        else:
            channel, sign = turn, sides["right"]
            how = "the tracks answered with opposite signs (drive: turn; right forward = left)"
        if channel in self._axis_map:
            self._finding(MISMATCH, f"axis {axis} also drives {channel}: not mapped")
            return
        self._axis_map[channel] = (axis, sign)
        self._record_axis(
            channel,
            axis,
            sign,
            f"a pulse of {self.config.scan_axis_value:+d} on axis {axis}: {how}",
        )

    def _record_axis(self, channel: str, axis: int, sign: int, how: str) -> None:
        self.operator.say(f"axis {axis} -> {channel}, sign {sign:+d}")
        self._measure(Measured(f"channels.{channel}.axis", axis, how))
        self._measure(Measured(f"channels.{channel}.axis_sign", sign, how))
