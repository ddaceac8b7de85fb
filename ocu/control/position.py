"""Joint position control on the OCU side, through velocity commands, under radio delay (no Qt).

The vendor protocol carries only velocities; telemetry may come once per second, 100-200 ms
late, lost, reordered and noisy. The paper's controller drives at one constant speed until a
reading shows the target passed: it overshoots and hunts. A controller that resets its
prediction to each reading does better on a perfect link, but a reading is a picture of the
past: the joint has moved since it was taken, and commands are still in flight.

This controller is a Smith predictor. Per joint it keeps the integral I(t) of every velocity
sent on the joint's channel (by anyone: keys, sliders, this controller) and one unknown, the
offset b between the joint's angle and that integral. A reading taken by the robot when the
commands sent up to `received_at - delay` had landed says b = angle - I(received_at - delay);
a one-state Kalman filter merges such observations (each reading is trusted fully while the
joint moves, and averaged when it stands still and the readings are noisy). Then

- the angle the joint will end at once every sent command has landed is b + I(now): the
  controller steers that one to the target, so commands in flight are never sent twice;
- the angle the joint has now is b + I(now - delay/2): the predictive display draws it.

The delay is measured online by the link (ocu.link.delay) and comes with every reading. The
speed is proportional to the predicted error, bounded by the channel's maximum, lifted to the
servo's starting speed, and its gain shrinks as the delay grows (seed 003 §4.1: delay eats
phase margin; a model error of the servo's speed is corrected one delay late). "Reached" is
said only when a reading taken after the joint's last command landed confirms it within the
band; a joint whose readings are too noisy to confirm gives up after a settle timeout with a
message instead of hunting forever. The stall check compares a reading's travel with the
travel commanded one delay earlier. The model counts what the robot does with a command: below
a servo's starting speed nothing, and on a `locked_while_driving` channel (the waist) nothing
while the same command drives the chassis (`driving`). A joint whose reading is implausible (see
ocu.control.plausibility) is never acted on.

Ticks come late. The command chosen at one tick is what the link keeps sending, at its own
rate from its own thread, until the next tick changes it; a caller on a busy thread (the
console's GUI thread under load) ticks every 50 ms one moment and every 300 ms the next. So
the speed is bounded by what the *horizon* allows — the error divided by the longest tick
interval seen lately, with a margin — not by the last interval. Each motion also carries the
time the joint reaches the target, and the link ends it then by itself (Command.until): a
tick later than any horizon finds the joint stopped at the target. A joint is never reversed
on the prediction alone: when the estimate says a joint went past its target, it stops, and
it is driven back only once a reading taken after that stop landed shows it is really past.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass

from ocu.control.commands import VelocityLimits
from ocu.profile import Motor, RobotProfile
from ocu.records import JointReading

DEFAULT_MAX_GAIN_PER_S = 10.0
# The gain times the delay is kept at or below this: a servo 50 % off its commanded speed
# then still leaves the delayed correction loop a phase margin above 30°.
DEFAULT_GAIN_DELAY_PRODUCT = 1.5
DEFAULT_TOLERANCE_RAD = math.radians(0.3)
# A moving joint stops when its predicted error is within this share of the tolerance.
STOP_FRACTION = 0.5
# A target counts as reached when the estimate, widened by three times its uncertainty, lies
# in this band (the settle band the benchmarks measure against). Three, not two: the test is
# repeated at every reading until it passes, and the first pass is the likeliest to be wrong.
REACHED_BAND_RAD = math.radians(0.5)
CONFIRM_SIGMAS = 3.0
STALE_PERIODS = 2.5  # telemetry periods, but never under STALE_MIN_S (a 50 Hz arm's
STALE_MIN_S = 0.25  # readings would go stale on one 50 ms stall of a busy machine)
STALL_MIN_COMMANDED_RAD = math.radians(2.0)
STALL_NOISE_SIGMAS = 6.0
STALL_FRACTION = 0.25
STALL_PACKETS = 2
LIMIT_MARGIN_RAD = math.radians(0.5)
DEFAULT_PERIOD_S = 0.05
# The next tick is assumed to come within this many times the longest tick interval of the last
# HORIZON_WINDOW_S (a busy caller's ticks are late and irregular), at most MAX_HORIZON_S.
HORIZON_MARGIN = 1.5
HORIZON_WINDOW_S = 3.0
MAX_HORIZON_S = 1.0
# Kalman filter of the offset b: the servo's speed may differ from the command by this share
# of the travel, and readings are never trusted below the encoder's resolution.
MODEL_SPEED_ERROR = 0.05
DRIFT_RAD_PER_S = math.radians(0.01)
NOISE_FLOOR_RAD = math.radians(0.01)
# A reading taken while the joint moves at v is off by v times the error of its delay.
DELAY_SIGMA_S = 0.03
NOISE_PRIOR_RAD = math.radians(0.2)
NOISE_ALPHA = 0.1
# An observation this many standard deviations off means the model, not the reading, failed.
OUTLIER_SIGMAS = 4.0
# The first samples of the reading noise are averaged, later ones smoothed with NOISE_ALPHA.
NOISE_AVERAGE_SAMPLES = 8
# Consecutive readings closer than this in commanded travel show the reading noise (less
# the model's own error over that travel).
NOISE_PAIR_TRAVEL_RAD = math.radians(5.0)
# Give up confirming after this many telemetry periods (plus two delays), 4 s at least.
SETTLE_PERIODS = 8.0
MIN_SETTLE_TIMEOUT_S = 4.0
# History of sent velocities kept per joint (longer than any delay the link measures).
HISTORY_S = 10.0


class PositionError(ValueError):
    """A target that cannot be controlled: unknown joint, no position feedback, off limits."""


class JointPredictor:
    """What the OCU believes about one joint: the commanded integral and the offset b.

    Times are the OCU's monotonic seconds. See the module docstring for the model.
    """

    def __init__(self) -> None:
        # Breakpoints of the piecewise-constant velocity: (time, velocity, I, A) where I is
        # the integral of the velocity and A of its magnitude, both up to that time.
        self._times: list[float] = []
        self._points: list[tuple[float, float, float]] = []
        self.offset_rad: float | None = None
        self.variance: float = 0.0
        self.noise_var: float = NOISE_PRIOR_RAD**2
        self.noise_samples = 0
        self.last_angle_rad: float | None = None
        self.last_received_at: float | None = None
        self.last_taken_at: float | None = None
        self._last_observation: tuple[float, float] | None = None  # (b_obs, A at taken)
        # When the last command ends by itself (its zero is the last breakpoint), if later
        # than the last command.
        self._end_at: float | None = None

    # ---- commands --------------------------------------------------------------------------

    def command(self, at: float, velocity: float, until: float | None = None) -> None:
        """The velocity sent from `at` on (to `until`: the link ends it then, Command.until)."""
        if self._end_at is not None and at < self._end_at:
            # The pending end was not reached: this command replaces it.
            self._times.pop()
            self._points.pop()
        self._end_at = None
        self._step_to(at, velocity)
        if until is not None and velocity != 0.0 and until > max(at, self._times[-1]):
            self._step_to(until, 0.0)
            self._end_at = until

    def _step_to(self, at: float, velocity: float) -> None:
        if self._times:
            at = max(at, self._times[-1])
            previous_v = self._points[-1][0]
            if previous_v == velocity:
                return
            integral, travel = self._integrals(at)
            if at == self._times[-1]:
                self._times.pop()
                self._points.pop()
        else:
            integral = travel = 0.0
        self._times.append(at)
        self._points.append((velocity, integral, travel))
        self._trim(at - HISTORY_S)

    @property
    def last_change_at(self) -> float | None:
        """When the sent velocity last changed (None: never sent)."""
        return self._times[-1] if self._times else None

    def velocity(self, at: float) -> float:
        """The velocity sent at a time (0 before anything was sent)."""
        index = bisect.bisect_right(self._times, at) - 1
        return self._points[index][0] if index >= 0 else 0.0

    def _integrals(self, at: float) -> tuple[float, float]:
        index = bisect.bisect_right(self._times, at) - 1
        if index < 0:
            return (self._points[0][1], self._points[0][2]) if self._points else (0.0, 0.0)
        velocity, integral, travel = self._points[index]
        dt = at - self._times[index]
        return integral + velocity * dt, travel + abs(velocity) * dt

    def integral(self, at: float) -> float:
        """∫ of the sent velocity up to `at` (an arbitrary but fixed origin)."""
        return self._integrals(at)[0]

    def travel(self, start: float, end: float) -> float:
        """∫ |sent velocity| between two times."""
        return abs(self._integrals(end)[1] - self._integrals(start)[1])

    def _trim(self, before: float) -> None:
        cut = bisect.bisect_right(self._times, before) - 1
        if cut > 0:
            del self._times[:cut]
            del self._points[:cut]

    # ---- readings --------------------------------------------------------------------------

    def on_reading(self, angle_rad: float, received_at: float, delay_s: float) -> None:
        """A plausible reading, taken by the robot when commands sent `delay_s` earlier landed."""
        taken_at = received_at - delay_s
        integral, travel = self._integrals(taken_at)
        observed = angle_rad - integral
        # A reading of a moving joint is also off by its speed times the delay's error.
        delay_var = (self.velocity(taken_at) * DELAY_SIGMA_S) ** 2
        if self.offset_rad is None or self.last_taken_at is None:
            self.offset_rad = observed
            self.variance = self.noise_var + delay_var
        else:
            moved = abs(travel - self._last_travel())
            elapsed = max(taken_at - self.last_taken_at, 0.0)
            self.variance += (MODEL_SPEED_ERROR * moved) ** 2 + (DRIFT_RAD_PER_S * elapsed) ** 2
            measurement_var = self.noise_var + delay_var
            innovation = observed - self.offset_rad
            model_failed = innovation * innovation > OUTLIER_SIGMAS**2 * (
                self.variance + measurement_var
            )
            if model_failed:
                # Far more than the filter expects: the model is wrong (a servo slower than
                # commanded, a joint pushed by hand). Believe the reading, not the model.
                self.variance = innovation * innovation
            gain = self.variance / (self.variance + measurement_var)
            self.offset_rad += gain * innovation
            self.variance *= 1.0 - gain
            if (
                self._last_observation is not None
                and moved <= NOISE_PAIR_TRAVEL_RAD
                and not model_failed
            ):
                # Two observations of the offset differ by the noise of two readings and the
                # model's speed error over the travel between them. (Their delay errors are
                # mostly the same and cancel; what is left counts as noise, the safe side.)
                difference = observed - self._last_observation[0]
                model_var = (MODEL_SPEED_ERROR * moved) ** 2
                sample = max((difference * difference - model_var) / 2.0, NOISE_FLOOR_RAD**2)
                previous = self.noise_var
                self.noise_samples += 1
                if self.noise_samples == 1:
                    self.noise_var = sample
                elif self.noise_samples <= NOISE_AVERAGE_SAMPLES:
                    self.noise_var += (sample - self.noise_var) / self.noise_samples
                else:
                    self.noise_var += NOISE_ALPHA * (sample - self.noise_var)
                # The estimate leaned on readings believed as good as the old noise estimate
                # said: its uncertainty scales with it.
                self.variance *= self.noise_var / previous
        self._last_observation = (observed, travel)
        self.last_angle_rad = angle_rad
        self.last_received_at = received_at
        self.last_taken_at = taken_at

    def _last_travel(self) -> float:
        return self._last_observation[1] if self._last_observation is not None else 0.0

    @property
    def known(self) -> bool:
        """Whether a reading has arrived."""
        return self.offset_rad is not None

    @property
    def sigma_rad(self) -> float:
        """Standard deviation of the estimate."""
        return math.sqrt(max(self.variance, 0.0))

    @property
    def noise_rad(self) -> float:
        """Estimated standard deviation of one reading."""
        return math.sqrt(self.noise_var)

    def eventual(self, now: float) -> float:
        """Where the joint ends up once every command sent until now has landed."""
        assert self.offset_rad is not None
        return self.offset_rad + self.integral(now)

    def current(self, now: float, delay_s: float) -> float:
        """Where the joint is now (commands need half the round trip to land)."""
        assert self.offset_rad is not None
        return self.offset_rad + self.integral(now - delay_s / 2.0)


@dataclass
class _Track:
    """A joint under position control."""

    motor: Motor
    target_rad: float
    started_at: float | None = None
    # Whether the joint holds still near its target (corrections then need a clear error).
    holding: bool = False
    near_since: float | None = None
    stall_packets: int = 0
    velocity_rad_s: float = 0.0
    # The sign the joint was last driven with (0: not yet): reversing it needs a reading.
    direction: float = 0.0
    # When the motion last commanded reaches the target (the link ends it then).
    until: float | None = None


class PositionController:
    """Drives several joints to target angles at once; see the module docstring."""

    def __init__(
        self,
        profile: RobotProfile,
        limits: VelocityLimits,
        *,
        max_gain_per_s: float = DEFAULT_MAX_GAIN_PER_S,
        gain_delay_product: float = DEFAULT_GAIN_DELAY_PRODUCT,
        tolerance_rad: float = DEFAULT_TOLERANCE_RAD,
        stale_after_s: float | None = None,
        settle_timeout_s: float | None = None,
    ) -> None:
        self.profile = profile
        self.limits = limits
        self.max_gain_per_s = max_gain_per_s
        self.gain_delay_product = gain_delay_product
        self.tolerance_rad = tolerance_rad
        period_s = 1.0 / profile.link.telemetry_rate_hz
        self._stale_base_s = (
            max(STALE_PERIODS * period_s, STALE_MIN_S) if stale_after_s is None else stale_after_s
        )
        self._settle_base_s = (
            max(MIN_SETTLE_TIMEOUT_S, SETTLE_PERIODS * period_s)
            if settle_timeout_s is None
            else settle_timeout_s
        )
        self.predictors: dict[str, JointPredictor] = {
            motor.name: JointPredictor() for motor in profile.positioned_motors
        }
        self._channel_joint = {
            motor.channel: motor.name for motor in profile.positioned_motors if motor.channel
        }
        self.delay_s: float | None = None
        # Whether the last command sent moves the chassis: the robot then refuses to turn
        # its `locked_while_driving` channels (the waist).
        self.driving = False
        # When the link is to end each channel of the last update's output (Command.until).
        self.until: dict[str, float] = {}
        self.faults: dict[str, str] = {}
        self._tracks: dict[str, _Track] = {}
        self._messages: list[str] = []
        self._last_update_at: float | None = None
        self._period_s = DEFAULT_PERIOD_S
        # (time, interval) of the recent ticks: the horizon a command must be safe over.
        self._intervals: deque[tuple[float, float]] = deque()

    # ---- derived settings ------------------------------------------------------------------

    @property
    def gain_per_s(self) -> float:
        """The proportional gain now: the maximum, reduced as the measured delay grows."""
        delay = self.delay_s or 0.0
        if delay <= 0.0:
            return self.max_gain_per_s
        return min(self.max_gain_per_s, self.gain_delay_product / delay)

    @property
    def tick_horizon_s(self) -> float:
        """How long a command chosen now may stay on the wire: the longest tick interval of
        the last few seconds, with a margin (ticks on a busy thread come late)."""
        longest = max((dt for _, dt in self._intervals), default=self._period_s)
        return min(HORIZON_MARGIN * max(longest, self._period_s), MAX_HORIZON_S)

    @property
    def stale_after_s(self) -> float:
        """A joint under control stops when its readings are this old (grows with the delay)."""
        return self._stale_base_s + (self.delay_s or 0.0)

    @property
    def settle_timeout_s(self) -> float:
        """How long a joint near its target may take to confirm it."""
        return self._settle_base_s + 2.0 * (self.delay_s or 0.0)

    # ---- targets ---------------------------------------------------------------------------

    def set_target(self, joint: str, angle_rad: float) -> None:
        """Start moving a joint to an angle; PositionError if it cannot be controlled."""
        motor = self.profile.motors.get(joint)
        if motor is None or motor.channel is None:
            raise PositionError(f"{joint}: not a joint driven by a velocity channel")
        if motor.limits_rad is None:
            raise PositionError(f"{joint}: has no position feedback")
        if not math.isfinite(angle_rad):
            raise PositionError(f"{joint}: target must be a finite number")
        low, high = motor.limits_rad
        if not low <= angle_rad <= high:
            raise PositionError(
                f"{joint}: target {math.degrees(angle_rad):.1f}° outside the limits "
                f"[{math.degrees(low):.1f}°, {math.degrees(high):.1f}°]"
            )
        fault = self.faults.get(joint)
        if fault is not None:
            raise PositionError(f"{joint}: its reading is implausible ({fault})")
        self._tracks[joint] = _Track(motor=motor, target_rad=angle_rad)

    def cancel(self, joint: str | None = None) -> None:
        """Drop one target (a manual command took the joint back) or all of them."""
        if joint is None:
            self._tracks.clear()
        else:
            self._tracks.pop(joint, None)

    @property
    def targets(self) -> dict[str, float]:
        """Joint name to target angle for every joint under control."""
        return {name: track.target_rad for name, track in self._tracks.items()}

    def channel_of(self, joint: str) -> str:
        """The velocity channel that drives a joint."""
        channel = self.profile.motors[joint].channel
        assert channel is not None
        return channel

    def predicted_angle(self, joint: str, now: float | None = None) -> float | None:
        """The angle the joint has now by the prediction (None before its first reading).

        Without `now`, the angle at the last update (where the controller steers from).
        """
        predictor = self.predictors.get(joint)
        if predictor is None or not predictor.known:
            return None
        at = self._last_update_at if now is None else now
        if at is None:
            return predictor.last_angle_rad
        return predictor.current(at, self.delay_s or 0.0)

    def predicted_angles(self, now: float) -> dict[str, float]:
        """Every joint's predicted angle now (joints with a reading and plausible)."""
        delay = self.delay_s or 0.0
        return {
            name: predictor.current(now, delay)
            for name, predictor in self.predictors.items()
            if predictor.known and name not in self.faults
        }

    def eventual_angles(self, now: float) -> dict[str, float]:
        """Where every joint ends once every command sent until `now` has landed (the Smith
        predictor's offset plus the integral of what was sent)."""
        return {
            name: predictor.eventual(now)
            for name, predictor in self.predictors.items()
            if predictor.known and name not in self.faults
        }

    def pop_messages(self) -> list[str]:
        """Why joints stopped since the last call (reached, stale, stalled, at limit, ...)."""
        messages, self._messages = self._messages, []
        return messages

    # ---- inputs ----------------------------------------------------------------------------

    def note_sent(
        self,
        now: float,
        velocities: Mapping[str, float],
        until: Mapping[str, float] | None = None,
    ) -> None:
        """The whole command that went to the robot at `now` (channels missing are zero;
        `until`: the channels the link ends by itself, and when: Command.until)."""
        ends = until or {}
        channels = self.profile.channels
        self.driving = any(
            abs(float(velocities.get(name, 0.0))) >= channels[name].min_speed
            for name in self.profile.drive_channels or ()
        )
        for channel, joint in self._channel_joint.items():
            velocity = float(velocities.get(channel, 0.0))
            # Below its starting speed the servo does not move (documents): the model agrees.
            if abs(velocity) < channels[channel].min_speed:
                velocity = 0.0
            # Nor does a channel the robot locks while the chassis moves (the waist).
            if self.driving and channels[channel].locked_while_driving:
                velocity = 0.0
            self.predictors[joint].command(now, velocity, ends.get(channel))

    def on_telemetry(
        self,
        readings: Mapping[str, JointReading],
        received_at: float,
        delay_s: float | None = None,
    ) -> None:
        """Correct every joint's estimate from one telemetry packet."""
        if delay_s is not None:
            self.delay_s = delay_s
        delay = self.delay_s or 0.0
        for name, reading in readings.items():
            predictor = self.predictors.get(name)
            if predictor is None or reading.angle_rad is None:
                continue
            if reading.fault is not None:
                self.faults[name] = reading.fault
                if name in self._tracks:
                    self._finish(name, f"{name}: stopped, reading implausible: {reading.fault}")
                continue
            self.faults.pop(name, None)
            previous_angle = predictor.last_angle_rad
            previous_taken = predictor.last_taken_at
            predictor.on_reading(reading.angle_rad, received_at, delay)
            track = self._tracks.get(name)
            if track is not None and previous_angle is not None and previous_taken is not None:
                self._check_motion(name, track, predictor, previous_angle, previous_taken)

    def _check_motion(
        self,
        name: str,
        track: _Track,
        predictor: JointPredictor,
        previous_angle: float,
        previous_taken: float,
    ) -> None:
        assert predictor.last_angle_rad is not None
        assert predictor.last_taken_at is not None
        commanded = predictor.integral(predictor.last_taken_at) - predictor.integral(previous_taken)
        moved = predictor.last_angle_rad - previous_angle
        threshold = max(STALL_MIN_COMMANDED_RAD, STALL_NOISE_SIGMAS * predictor.noise_rad)
        if abs(commanded) >= threshold and (
            moved * commanded <= 0 or abs(moved) < STALL_FRACTION * abs(commanded)
        ):
            track.stall_packets += 1
            if track.stall_packets >= STALL_PACKETS:
                self._finish(
                    name,
                    f"{name}: stopped, does not move as commanded "
                    f"({math.degrees(moved):+.1f}° for {math.degrees(commanded):+.1f}°)",
                )
        else:
            track.stall_packets = 0

    # ---- output ----------------------------------------------------------------------------

    def note_tick(self, now: float) -> None:
        """A control tick at `now` (update() calls it): the interval goes into the horizon.

        Idempotent for one time; callers that tick without update() (the arm) call it."""
        last = self._last_update_at
        if last is not None and now > last:
            self._period_s = now - last
            self._intervals.append((now, self._period_s))
            while self._intervals and self._intervals[0][0] < now - HORIZON_WINDOW_S:
                self._intervals.popleft()
        if last is None or now > last:
            self._last_update_at = now

    def update(self, now: float) -> dict[str, float]:
        """Velocity per channel (rad/s) for every joint under control, at time now.

        A joint that finished in this step has no entry: its channel must be zeroed.
        """
        self.note_tick(now)
        self.until = {}
        output: dict[str, float] = {}
        for name, track in list(self._tracks.items()):
            channel = self.channel_of(name)
            velocity = self._step(name, track, now)
            if name not in self._tracks:
                continue  # finished: its channel is no longer the controller's (caller zeroes)
            track.velocity_rad_s = velocity
            output[channel] = velocity
            if velocity != 0.0 and track.until is not None:
                self.until[channel] = track.until
        return output

    def _step(self, name: str, track: _Track, now: float) -> float:
        predictor = self.predictors[name]
        if track.started_at is None:
            track.started_at = now
        if not predictor.known or predictor.last_received_at is None:
            if now - track.started_at > self.stale_after_s:
                self._finish(name, f"{name}: stopped, no telemetry for this joint")
            return 0.0
        age = now - predictor.last_received_at
        if age > self.stale_after_s and now - track.started_at > self.stale_after_s:
            self._finish(name, f"{name}: stopped, telemetry stale ({age:.1f} s old)")
            return 0.0
        estimate = predictor.eventual(now)
        error = track.target_rad - estimate
        sigma = predictor.sigma_rad
        # Moving, the joint stops in the middle of the tolerance, leaving room for the small
        # errors of the model. Holding still near the target, a correction starts only when
        # the estimate is out of the tolerance by more than its own uncertainty: noisy
        # readings must not make the joint twitch back and forth, and a confident estimate
        # just outside must not leave it waiting for a confirmation that cannot come.
        if track.holding:
            correct = abs(error) > self.tolerance_rad and abs(error) > 2.0 * sigma
        else:
            correct = abs(error) > STOP_FRACTION * self.tolerance_rad
        if not correct:
            track.holding = True
            if track.near_since is None:
                track.near_since = now
            if self._confirmed(predictor, error, now):
                self._finish(name, f"{name}: reached {math.degrees(track.target_rad):.1f}°")
            elif now - track.near_since > self.settle_timeout_s:
                self._finish(
                    name,
                    f"{name}: stopped near {math.degrees(track.target_rad):.1f}° without "
                    f"confirming ±{math.degrees(self.tolerance_rad):.1f}°: readings scatter "
                    f"±{math.degrees(predictor.noise_rad):.1f}° (σ), estimate "
                    f"{math.degrees(estimate):.2f}° ± {math.degrees(sigma):.2f}°",
                )
            return 0.0
        track.holding = False
        channel = self.profile.channels[self.channel_of(name)]
        v_max = self.limits.get(channel.name)
        if v_max <= 0.0:
            return 0.0
        direction = math.copysign(1.0, error)
        if track.direction and direction != track.direction and not self.may_reverse(name):
            # Past the target by the prediction alone: stop, and let a reading taken after
            # the stop say whether the joint is really past (the prediction assumed a tick
            # that came late, or the servo ran faster than modelled). Held, a small overshoot
            # within the tolerance is then left alone.
            track.holding = True
            return 0.0
        # Lifted to the servo's smallest moving speed, but never so fast that the command
        # would carry the joint past the target before the next tick, however late it comes
        # (within the horizon). Below the starting speed the servo does not move: a joint
        # within the tolerance then holds; one further off takes the starting speed.
        speed = min(max(self.gain_per_s * abs(error), channel.min_speed), v_max)
        speed = min(speed, abs(error) / self.tick_horizon_s)
        if speed < channel.min_speed:
            if abs(error) <= self.tolerance_rad:
                track.holding = True
                if track.near_since is None:
                    track.near_since = now
                if self._confirmed(predictor, error, now):
                    self._finish(name, f"{name}: reached {math.degrees(track.target_rad):.1f}°")
                return 0.0
            speed = channel.min_speed
        limits = track.motor.limits_rad
        measured = predictor.last_angle_rad
        if limits is not None and measured is not None:
            low, high = limits
            at_low = error < 0 and measured <= low + LIMIT_MARGIN_RAD
            at_high = error > 0 and measured >= high - LIMIT_MARGIN_RAD
            if at_low or at_high:
                self._finish(name, f"{name}: stopped at its limit")
                return 0.0
        track.direction = direction
        # The link ends this motion by itself when the joint would reach the target: a late
        # next tick cannot carry it past (Command.until).
        track.until = now + abs(error) / speed
        return math.copysign(speed, error)

    def may_reverse(self, joint: str) -> bool:
        """Whether a joint may be driven back against its motion: only once a reading taken
        after its last velocity change landed shows where it is (never on a prediction)."""
        return read_since_change(self.predictors[joint])

    def _confirmed(self, predictor: JointPredictor, error: float, now: float) -> bool:
        """The joint's channel sends zero, and a reading taken after the last velocity change
        landed puts the estimate in the band."""
        if predictor.velocity(now) != 0.0 or not read_since_change(predictor):
            return False
        return (
            abs(error) <= self.tolerance_rad
            and abs(error) + CONFIRM_SIGMAS * predictor.sigma_rad <= REACHED_BAND_RAD
        )

    def _finish(self, name: str, message: str) -> None:
        self._tracks.pop(name, None)
        self._messages.append(message)


def read_since_change(predictor: JointPredictor) -> bool:
    """Whether a reading was taken after the joint's last velocity change had landed: the
    estimate then rests on a picture of the joint under the command now in force."""
    if predictor.last_taken_at is None:
        return False
    changed_at = predictor.last_change_at
    return changed_at is None or predictor.last_taken_at >= changed_at
