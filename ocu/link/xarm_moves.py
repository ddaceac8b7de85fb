"""The xArm link's moves: a command's velocities and goals into CMD_SERVO_MOVE frames.

`XarmMoves` keeps the link's copy of each servo's setpoint as the board moves it (from where
it was to a move's target over the move's time: `Ramp`), known from the servo's first
believable reading on. From a command (docs/xarm.md "The link"):

- a joint with a velocity: a jog move from its setpoint to where the velocity takes it in
  `jog_move_s`, within `jog_move_s` (sent every jog period: if the stream stops, the servos
  stop within `jog_move_s`). The setpoint is kept in fractions of a unit: the board takes
  whole units, and a slow jog whose step is under half a unit would otherwise never move;
- a joint with a goal (`Command.goals`: a position command with a duration): one move to the
  goal within the time left to its `until`, sent once; the joints of one goal with the same
  end go in one frame (one synchronized move of the board), which takes longer than that
  only when a joint would have to go faster than its top speed (a goal that came late);
- a joint whose velocity went to zero while its setpoint moves: the stop move, the setpoint
  held where it is now, within 0 ms (none for a timed move already at its goal's unit).

Targets are clamped to the joint's limits (a jog never carries a joint further out past
one), velocities to its top speed. A joint never read is not moved.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from ocu.link.xarm_wire import Ramp
from ocu.profile.xarm import XarmJoint, XarmProfile
from ocu.protocol.xarm import DURATION_MAX_MS, POSITION_MAX, POSITION_MIN, servo_move
from ocu.records import Command


def _units(value: float) -> int:
    return int(max(POSITION_MIN, min(POSITION_MAX, round(value))))


class XarmMoves:
    """The setpoints and the frames that move them (the caller holds its lock)."""

    def __init__(self, arm: XarmProfile) -> None:
        self.arm = arm
        self.ramps: dict[int, Ramp] = {}  # servo id -> its setpoint (known after a reading)
        # servo id -> the (goal, end) of the timed move sent for it and not stopped since.
        self._timed: dict[int, tuple[float, float]] = {}

    def first_reading(self, servo: int, raw: int, now: float) -> None:
        """A servo's first believable reading: the setpoint the board holds is where it is."""
        if servo not in self.ramps:
            held = _units(raw)
            self.ramps[servo] = Ramp(held, held, now, 0.0)

    def moving(self, now: float) -> bool:
        """Whether a setpoint is still on its way."""
        return any(ramp.moving(now) for ramp in self.ramps.values())

    def setpoints(self, now: float) -> dict[int, float]:
        """Each known servo's setpoint now (servo units)."""
        return {servo: ramp.value(now) for servo, ramp in self.ramps.items()}

    def frames(self, command: Command, now: float) -> tuple[list[bytes], Command]:
        """The frames for the command now, and the command they carry (its velocities as
        sent: zero for the joints not moved)."""
        command = command.expired(now)
        stops: dict[int, int] = {}
        jogs: dict[int, int] = {}
        timed: dict[float, dict[int, tuple[int, float, float]]] = {}  # end -> servo -> move
        sent: dict[str, float] = {}
        move_s = self.arm.timing.jog_move_s
        for joint in self.arm.joints:
            ramp = self.ramps.get(joint.servo)
            if ramp is None:
                continue  # never read: where it is is not known, so it is not moved
            here = ramp.value(now)
            goal = command.goals.get(joint.name)
            if goal is not None and command.until[joint.name] > now:
                key = (goal, command.until[joint.name])
                if self._timed.get(joint.servo) != key:
                    self._timed[joint.servo] = key
                    # Never faster than the joint's top speed (a goal that comes late).
                    slowest = abs(self._goal_units(joint, goal) - here) / (
                        joint.max_speed_rad_s * self.arm.units_per_rad
                    )
                    timed.setdefault(key[1], {})[joint.servo] = (
                        self._goal_units(joint, goal),
                        here,
                        slowest,
                    )
                sent[joint.name] = command.velocity(joint.name)
                continue
            was_timed = self._timed.pop(joint.servo, None) is not None
            limit = joint.max_speed_rad_s
            velocity = max(-limit, min(limit, command.velocity(joint.name)))
            if velocity == 0.0:
                # A timed move whose setpoint is already at its goal's unit (its last
                # millisecond: its duration is rounded up to whole ms) needs no stop move: it
                # would hold the servo where the move ends anyway. A jog always gets one.
                ending = was_timed and _units(here) == _units(ramp.end)
                if ramp.moving(now) and not ending:
                    stops[joint.servo] = self._hold(joint.servo, ramp, here, now)
                continue
            step = joint.sign * velocity * self.arm.units_per_rad * move_s
            end = self._limited(joint, here, step)
            jogs[joint.servo] = _units(end)
            self.ramps[joint.servo] = Ramp(here, end, now, move_s)
            sent[joint.name] = velocity
        frames = []
        if stops:
            frames.append(servo_move(0, stops))
        for end, group in sorted(timed.items()):
            # One duration for the group: the time left to its end, or longer when a joint
            # could not make it at its top speed (all of them stay synchronized).
            duration_s = max(end - now, *(slowest for _, _, slowest in group.values()))
            duration_ms = min(math.ceil(duration_s * 1000.0), DURATION_MAX_MS)
            for servo, (target, here, _) in group.items():
                self.ramps[servo] = Ramp(here, target, now, duration_ms / 1000.0)
            frames.append(servo_move(duration_ms, {s: t for s, (t, _, _) in group.items()}))
        if jogs:
            frames.append(servo_move(round(move_s * 1000), jogs))
        return frames, command.with_velocities(
            {name: sent.get(name, 0.0) for name in self.arm.joint_names}
        )

    def _goal_units(self, joint: XarmJoint, goal_rad: float) -> int:
        """A goal as the servo's position, within the joint's limits."""
        raw = self.arm.raw_units(joint, goal_rad)
        return _units(max(joint.min_units, min(joint.max_units, raw)))

    @staticmethod
    def _limited(joint: XarmJoint, here: float, step: float) -> float:
        """Where a jog step from `here` may go: never further out past a limit (a servo found
        beyond one, or carried past it, stays there until jogged back in), and never
        backwards to the limit (a jog outward from beyond it does not pull the joint in)."""
        if step > 0:
            target = min(here + step, max(joint.max_units, here))
        else:
            target = max(here + step, min(joint.min_units, here))
        return max(POSITION_MIN, min(POSITION_MAX, target))

    def _hold(self, servo: int, ramp: Ramp, here: float, now: float) -> int:
        """Stop a setpoint where it is: the target of the stop move."""
        target = _units(here)
        ramp.start, ramp.end, ramp.at, ramp.duration_s = target, target, now, 0.0
        self._timed.pop(servo, None)
        return target

    def stop_frame(self, now: float) -> bytes | None:
        """The stop move: every known servo's setpoint held where it is now."""
        stops = {
            servo: self._hold(servo, ramp, ramp.value(now), now)
            for servo, ramp in self.ramps.items()
        }
        return servo_move(0, stops) if stops else None

    def targets(self) -> Mapping[int, Ramp]:
        """The setpoints (for the readings' targets)."""
        return self.ramps
