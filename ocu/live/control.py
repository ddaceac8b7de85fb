"""Teleop from a live client (`--live-control`): a client's `/cmd_vel` and the arm's topics
(`/joint_goals`, `/arm/twist_cmd`, `/arm/named_pose`; ocu.live.goals) are the input mux's
`live` source (ocu/control/mux.md), under the same locks as every source (docs/live.md).

- One client commands at a time: the first that publishes; another is refused until the
  first has been silent for its timeout, unadvertised what it commanded on, or left.
- A stream's timeout follows its own rate (`/cmd_vel`, `/arm/twist_cmd`): 1.5 of its last
  interval between messages, at least MIN_TIMEOUT_S and at most the mux table's 0.6 s (the
  first message gets the 0.6 s), so a panel publishing once a second drives 0.6 s per
  message, not a second and more. A goal (`/joint_goals`, `/arm/named_pose`) is one message
  for one move: the client commands until the move ends, while each of its streams still
  stops on its own timeout. The server's loop expires them; the
  model's own timeout (the table's 0.6 s, the control thread) stops the source even if the
  server's thread stalls.
- A client that leaves or unadvertises stops what it drove at once.
- The model is reached under the control core's lock, never through the window's guarded
  handle (each of whose calls is the GUI's sign of life).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Final, Protocol

from ocu.console.channels import Source
from ocu.console.model import ConsoleModel
from ocu.control.position import PositionError
from ocu.kinematics.arm import ArmError
from ocu.live.goals import LiveGoals
from ocu.live.messages import (
    ARM_TWIST,
    CMD_VEL,
    ENCODINGS,
    JOINT_GOALS,
    NAMED_POSE,
    ArmTwist,
    InputError,
    JointGoal,
    decode,
    schemas_of,
)

# Foxglove's Teleop panel names the ROS 2 type, Lichtblick's the ROS 1 name.
TWIST_SCHEMAS: Final = schemas_of(CMD_VEL)
STREAMS: Final = (CMD_VEL, ARM_TWIST)
__all__ = ["ENCODINGS", "InputError", "TwistError", "decode_twist"]
MIN_TIMEOUT_S: Final = 0.15
PERIOD_FACTOR: Final = 1.5
# An interval longer than this is a new start, not the client's rate.
MAX_PERIOD_S: Final = 5.0
NOT_FREE: Final = "the drive is not free: the operator holds it, or the e-stop is latched"


REVOKED = "the operator has not allowed a remote drive"


TwistError = InputError


class Core(Protocol):
    """The control core's side the server needs (ocu.core.manager.ControllerManager)."""

    model: ConsoleModel
    lock: threading.RLock


def decode_twist(encoding: str, payload: bytes) -> tuple[float, float]:
    """(linear.x, angular.z) of a Twist in json or cdr; TwistError if it is not one."""
    linear, angular = decode(CMD_VEL, encoding, payload)
    return float(linear), float(angular)


class LiveControl:
    """The `live` source of one model: who commands, until when (module docstring).

    `goals`: the arm's topics (ocu.live.goals); without it only /cmd_vel is taken.
    """

    def __init__(
        self, core: Core, clock: Callable[[], float], goals: LiveGoals | None = None
    ) -> None:
        self.core = core
        self.clock = clock
        self.drive = core.model.profile.drive_channels
        self.goals = goals
        self.timeout_max_s = dict(core.model.mux.timed())[Source.LIVE.value]
        self._lock = threading.Lock()
        # The operator's permission: the console's LIVE indicator revokes and allows again
        # (ocu.widgets.live_status); --live-control itself allows.
        self._allowed = True
        self._owner: str | None = None
        self._topic = ""
        # The owner's streams and when each stops (its rate's timeout), and until when its
        # last goal holds the command at least (it holds on while the move goes on).
        self._streams: dict[str, float] = {}
        self._goal_until: float | None = None
        self._last: dict[tuple[str, str], float] = {}
        with core.lock:
            core.model.mux.register(Source.LIVE.value, self._stopped)

    def topics(self) -> tuple[str, ...]:
        """The topics a client may publish on to this robot."""
        drive = (CMD_VEL,) if self.drive is not None else ()
        if self.goals is None:
            return drive
        arm = (ARM_TWIST, NAMED_POSE) if self.goals.goals.arm_available else ()
        return (*drive, JOINT_GOALS, *arm)

    @property
    def owner(self) -> str | None:
        """The client commanding now (its address), or None."""
        with self._lock:
            return self._owner

    @property
    def allowed(self) -> bool:
        """Whether the operator lets a client drive."""
        with self._lock:
            return self._allowed

    def set_allowed(self, allowed: bool) -> None:
        """The operator allows a client to drive, or revokes it: the client driving stops at
        once, and nothing a client sends moves the robot until it is allowed again."""
        with self._lock:
            if allowed == self._allowed:
                return
            self._allowed = allowed
            owner, self._owner = self._owner, None
        word = "allowed" if allowed else "revoked"
        if not allowed and self.goals is not None:
            self.goals.stop("the operator revoked the remote drive")
        with self.core.lock:
            if not allowed:
                self.core.model.clear_source(Source.LIVE, "the operator revoked the remote drive")
            self.core.model.events.message.emit(
                f"remote drive {word} by the operator" + (f" ({owner} stopped)" if owner else "")
            )

    def _held(self, now: float, moving: bool) -> bool:
        """Whether the owner still commands (self._lock held): a stream not yet timed out,
        or a goal whose move goes on (`moving`: the goal core commands)."""
        streaming = any(now < deadline for deadline in self._streams.values())
        goal = self._goal_until is not None and (now < self._goal_until or moving)
        return streaming or goal

    def _claim(self, client: str, topic: str, now: float) -> tuple[str | None, float]:
        """Whether the client may command now (None, its timeout) or why not."""
        moving = self.goals is not None and self.goals.commanding  # not under self._lock
        with self._lock:
            if not self._allowed:
                return REVOKED, 0.0
            owner = self._owner
            if owner is not None and owner != client and self._held(now, moving):
                return f"{owner} commands {self._topic} now", 0.0
            if topic not in STREAMS:
                return None, self.timeout_max_s
            last = self._last.get((client, topic))
            period = None if last is None or now - last > MAX_PERIOD_S else now - last
            self._last[(client, topic)] = now
            if period is None:
                return None, self.timeout_max_s
            return None, min(max(PERIOD_FACTOR * period, MIN_TIMEOUT_S), self.timeout_max_s)

    def _took(self, client: str, topic: str, now: float, timeout: float) -> None:
        with self._lock:
            first = self._owner != client
            if first:
                self._streams, self._goal_until = {}, None
            self._owner = client
            self._topic = topic
            if topic in STREAMS:
                self._streams[topic] = now + timeout
            else:
                self._goal_until = now + timeout
        if first:
            with self.core.lock:
                self.core.model.events.message.emit(f"live client {client} drives ({topic})")

    def twist(self, client: str, linear_m_s: float, angular_rad_s: float) -> str | None:
        """One /cmd_vel from a client; None if taken, else why it was not."""
        now = self.clock()
        refusal, timeout = self._claim(client, CMD_VEL, now)
        if refusal is not None:
            return refusal
        if self.drive is None:
            return "this robot has no chassis"
        linear, turn = self.drive
        model = self.core.model
        with self.core.lock:
            if model.estopped:  # latched until the operator acts: nothing moves meanwhile
                return NOT_FREE
            applied = model.set_source_velocities(
                Source.LIVE, {linear: linear_m_s, turn: angular_rad_s}
            )
        if not applied:
            return NOT_FREE
        self._took(client, CMD_VEL, now, timeout)
        return None

    def command(self, client: str, topic: str, message: object) -> str | None:
        """One message on an arm topic (a JointGoal, an ArmTwist, a pose name); None if
        taken, else why it was not."""
        goals = self.goals
        if goals is None or topic not in self.topics():
            return f"{topic} is not taken by this robot"
        now = self.clock()
        refusal, timeout = self._claim(client, topic, now)
        if refusal is not None:
            return refusal
        with self.core.lock:
            if self.core.model.estopped:
                return NOT_FREE
        goals.settle()  # a stop of the source before this command halts what came before it
        core = goals.goals
        try:
            if isinstance(message, JointGoal):
                core.set_goals(message.names, message.positions_rad)
            elif isinstance(message, ArmTwist):
                if message.frame_id.lstrip("/") not in ("", self._arm_base()):
                    return f"frame {message.frame_id!r}: only {self._arm_base()!r} is understood"
                if not core.on_arm_twist(message.linear, message.angular):
                    return core.refusal() or "the link is not up"
            else:
                core.on_named_pose(str(message))
        except (PositionError, ArmError) as err:
            return str(err)
        self._took(client, topic, now, timeout)
        return None

    def _arm_base(self) -> str:
        arm = self.core.model.profile.arm
        return arm.base_link if arm is not None else ""

    def expire(self) -> None:
        """Stop each of the commanding client's streams once its timeout has passed, and let
        the client go when nothing it sent holds any more (a goal: once its move has ended)."""
        moving = self.goals is not None and self.goals.commanding  # not under self._lock
        now = self.clock()
        with self._lock:
            owner = self._owner
            if owner is None:
                return
            late = [topic for topic, deadline in self._streams.items() if now >= deadline]
            for topic in late:
                del self._streams[topic]
            held = self._held(now, moving)
        if not held:
            self.release(owner, "nothing within its timeout, no move going on")
        elif CMD_VEL in late and self.drive is not None:
            # Its drive stream went quiet while a goal of its goes on: the tracks stop.
            with self.core.lock:
                zeros = dict.fromkeys(self.drive, 0.0)
                self.core.model.set_source_velocities(Source.LIVE, zeros)

    def release(self, client: str, reason: str) -> None:
        """The client stops commanding (it left, unadvertised, timed out)."""
        with self._lock:
            for key in [key for key in self._last if key[0] == client]:
                del self._last[key]
            if self._owner != client:
                return
            self._owner = None
        if self.goals is not None:
            self.goals.stop(f"{client}: {reason}")
        with self.core.lock:
            self.core.model.clear_source(Source.LIVE, f"{client}: {reason}")

    def step(self) -> None:
        """The server's periodic work: the goals' step, then the timeouts."""
        if self.goals is not None:
            self.goals.step(self.clock())
        self.expire()

    def _stopped(self, _reason: str) -> None:
        # A lock or the operator stopped the source (the model's lock held): it needs new
        # input, and the next client to publish may take it.
        with self._lock:
            self._owner = None
        if self.goals is not None:
            self.goals.stop(_reason or "stopped")
        self.core.model.clear_source(Source.LIVE)
