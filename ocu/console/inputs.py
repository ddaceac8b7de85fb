"""The command's other inputs, a part of the console model: the game controller
(`Source.GAMEPAD`, a manual source with its own rule for taking a channel back), a planner
through ROS (`Source.ROS`, yielding to any manual input) and the arm in Cartesian space
(`Source.ARM`; ocu.console.arm calls `arm_starting` and `arm_output`)."""

from __future__ import annotations

from collections.abc import Mapping

from ocu.console.channels import PAD_AT_REST, PadWish, Source, check_finite
from ocu.console.part import ModelPart


class InputSources(ModelPart):
    """The game controller, a planner (ROS) and the arm as sources of the command."""

    # ---- the game controller (ocu.gamepad, through the window) -----------------------------

    def set_gamepad(
        self, fractions: Mapping[str, float], held: Mapping[str, int] | None = None
    ) -> None:
        """What the pad asks of each channel it maps; a channel left out is at rest.

        `fractions`: a stick's share of the channel's maximum, in [-1, 1]; `held`: a button's
        direction (-1, 0, 1), at the channel's hotkey speed. A channel becomes the pad's when
        its wish leaves rest (the latest manual input wins) and follows the wish while the
        pad holds it. Anything else that takes the channel meanwhile (a key, a slider, a
        target, a halt, an e-stop) keeps it until the pad's wish is back at rest: a stick
        still deflected never takes it back by itself.
        """
        held = held or {}
        wishes: dict[str, PadWish] = {}
        for channel in (*fractions, *held):
            self._check_channel(channel)
            fraction = check_finite(channel, fractions.get(channel, 0.0))
            direction = held.get(channel, 0)
            if direction not in (-1, 0, 1):
                raise ValueError(f"pad direction must be -1, 0 or 1, got {direction!r}")
            wishes[channel] = (min(max(fraction, -1.0), 1.0), direction)
        for channel in self._pad:
            wishes.setdefault(channel, PAD_AT_REST)
        taking = []
        for channel, wish in wishes.items():
            previous = self._pad.get(channel, PAD_AT_REST)
            self._pad[channel] = wish
            ours = self._requested(channel).source is Source.GAMEPAD
            if wish == PAD_AT_REST:
                self._pad_blocked.discard(channel)
                if ours:
                    self._set_channel(channel, 0.0, Source.NONE)
            elif channel in self._pad_blocked:
                continue
            elif ours:
                self._set_channel(channel, self._pad_velocity(channel), Source.GAMEPAD)
            elif previous == PAD_AT_REST:
                taking.append(channel)
            else:
                # Taken from the pad while its wish was away from rest.
                self._pad_blocked.add(channel)
        if taking:
            self._operator_acted()
            for channel in taking:
                self._take_manual(channel)
                self._set_channel(channel, self._pad_velocity(channel), Source.GAMEPAD)
        self._publish()

    def stop_arm(self, reason: str) -> bool:
        """The arm's automatic motion (a jog, a goal, a stored pose) stops now; True if it
        was moving. For inputs that started a move and let go (the pad's deadman)."""
        if self.arm is None:
            return False
        moving = any(self._channels[c].source is Source.ARM for c in self.arm.channels)
        self._stop_arm(reason)
        self._publish()
        return moving

    def stop_gamepad(self, reason: str) -> bool:
        """The pad lets go (deadman released, unplugged, stalled): its channels stop now.

        True if the pad was moving anything; its wishes are at rest afterwards.
        """
        moving = self.gamepad_channels
        self._pad = dict.fromkeys(self._pad, PAD_AT_REST)
        self._pad_blocked.clear()
        for channel in moving:
            self._set_channel(channel, 0.0, Source.NONE)
        self._publish()
        if moving:
            self.events.message.emit(f"gamepad motion stopped: {reason}")
        return bool(moving)

    @property
    def gamepad_channels(self) -> list[str]:
        """Channels the game controller drives now."""
        return [c for c in self._channels if self._requested(c).source is Source.GAMEPAD]

    def _pad_velocity(self, channel: str) -> float:
        fraction, direction = self._pad.get(channel, PAD_AT_REST)
        if direction:
            return direction * self.hotkey_speed(channel)
        return fraction * self.limits.get(channel)

    # ---- a planner (the ROS bridge, through the window) ------------------------------------

    def set_external_velocities(self, values: Mapping[str, float]) -> dict[str, float]:
        """Velocities from a planner (ROS), bounded like every input; what was applied.

        A channel the operator holds (a key, a slider, a typed value, a switch, a position
        target) stays the operator's: the latest manual input wins.
        """
        return self.set_source_velocities(Source.ROS, values)

    def clear_external(self) -> None:
        """The planner lost control: every channel it drives stops."""
        self.clear_source(Source.ROS)

    @property
    def external_channels(self) -> list[str]:
        """Channels a planner drives now."""
        return self.source_channels(Source.ROS)

    # ---- any source of the mux's table (a planner, a remote client) ------------------------

    def set_source_velocities(
        self, source: Source, values: Mapping[str, float]
    ) -> dict[str, float]:
        """Velocities from `source`, bounded like every input; what was applied.

        A channel goes to the source only when the mux's table lets it take the channel from
        whoever holds it (ocu/control/mux.md: the priorities); the others are left out of the
        result. A source with a timeout in seconds stops that long after this call unless
        called again. For the manual sources use their own methods.
        """
        rule = self.mux.rule(source.value)
        if rule.manual:
            raise ValueError(f"set_source_velocities takes no manual source ({source.value})")
        checked = {}
        for channel, raw in values.items():
            self._check_channel(channel)
            checked[channel] = check_finite(channel, raw)
        self._fed_at[source] = self.clock()
        applied: dict[str, float] = {}
        for channel, wanted in checked.items():
            if not self.mux.may_take(source.value, self._requested(channel).source.value):
                continue
            # The drive pair is bounded together when it is composed (turn radius kept).
            drive = channel in self._drive_request
            value = wanted if drive else self.limits.clamp(channel, wanted)
            self._set_channel(channel, value, source if value else Source.NONE)
            applied[channel] = self._channels[channel].velocity
        self._publish()
        return applied

    def set_source_ends(
        self, source: Source, until: Mapping[str, float], goals: Mapping[str, float]
    ) -> None:
        """When `source`'s channels end by themselves (Command.until), and the goals they
        reach then (Command.goals: a planner's arm move on hardware with timed moves); set
        before its velocities, which carry them to the command."""
        self._source_ends[source] = (dict(until), dict(goals))

    def clear_source(self, source: Source, reason: str = "") -> None:
        """Every channel `source` drives stops."""
        self._source_ends.pop(source, None)
        for channel in self._channels:
            if self._requested(channel).source is source:
                self._set_channel(channel, 0.0, Source.NONE)
        self._fed_at.pop(source, None)
        self._publish()
        if reason:
            self.events.message.emit(f"{source.value} stopped: {reason}")

    def source_channels(self, source: Source) -> list[str]:
        """Channels `source` drives now."""
        return [c for c in self._channels if self._requested(c).source is source]

    def _expire_sources(self, now: float) -> None:
        """Sources with a timeout in seconds stop that long after their last input."""
        for name, timeout_s in self.mux.timed():
            source = Source(name)
            fed_at = self._fed_at.get(source)
            if fed_at is not None and now - fed_at > timeout_s:
                del self._fed_at[source]
                if self.source_channels(source):
                    self.clear_source(source, f"no input for {timeout_s:g} s")

    # ---- the arm (ocu.console.arm calls these) ---------------------------------------------

    def arm_starting(self, *, move: bool) -> None:
        """The arm takes its channels: the operator acted (e-stop latch, ROS), position targets
        and held keys on its joints are dropped."""
        assert self.arm is not None
        self._operator_acted(keep_arm=True)
        for channel in self.arm.channels:
            joint = self._joint_of(channel)
            if joint is not None and joint in self._targets:
                self.controller.cancel(joint)
            self._drop_keys(channel)
            self._set_channel(channel, 0.0, Source.ARM)
        self._sync_targets()
        self._publish()

    def arm_output(self, velocities: Mapping[str, float]) -> None:
        """The arm's velocities now; its channels return to nobody when it commands nothing."""
        assert self.arm is not None
        active = self.arm.controller.active
        for channel in self.arm.channels:
            if self._channels[channel].source is not Source.ARM:
                continue
            if channel in velocities:
                self._set_channel(channel, velocities[channel], Source.ARM)
            else:
                self._set_channel(channel, 0.0, Source.ARM if active else Source.NONE)
        self._publish()

    def _stop_arm(self, reason: str) -> None:
        """The arm stops at once; its channels go to zero."""
        if self.arm is None:
            return
        self.arm.stop(reason)
        for channel in self.arm.channels:
            if self._channels[channel].source is Source.ARM:
                self._set_channel(channel, 0.0, Source.NONE)
