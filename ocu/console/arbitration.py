"""Who commands a channel, a part of the console model: the input mux's table
(ocu/control/mux.md, docs/console.md "Who commands a channel") applied - each source's stop
registered, what any operator input stops, what each lock stops, and the stops themselves."""

from __future__ import annotations

from collections.abc import Callable

from ocu.console.channels import Source
from ocu.console.part import ModelPart
from ocu.control.mux import OPERATOR, InputMux, MuxError

OPERATOR_TOOK_OVER = "operator took over"


class Arbitration(ModelPart):
    """The mux's rules applied to the model's channels."""

    def _init_mux(self, mux: InputMux | None) -> None:
        """Each source of the table registers its stop (a new source registers its own)."""
        self.mux = mux if mux is not None else InputMux.shipped()
        self._fed_at: dict[Source, float] = {}
        self._source_ends: dict[Source, tuple[dict[str, float], dict[str, float]]] = {}
        self._pad_background = False
        for zeroed in (Source.SLIDER, Source.TEXT, Source.SWITCH, Source.GAMEPAD, Source.ROS):
            self.mux.register(zeroed.value, self._zeroer(zeroed))
        self.mux.register(Source.HOTKEY.value, self._release_held)
        self.mux.register(Source.POSITION.value, self._stop_position)
        self.mux.register(Source.ARM.value, self._arm_stop)
        self.mux.register(Source.ASSIST.value, self._end_assist)
        self.mux.register(Source.TRACK.value, self._end_tracking)

    def _operator_acted(self, *, keep_arm: bool = False) -> None:
        """A motion input of the operator: the sources the mux's table says stop for it
        stop (a planner, an assisted mode, tracking, an arm moving to a goal), the e-stop
        latch lets go."""
        self.events.operator_acted.emit()
        stopped = self.mux.stopped_by(OPERATOR, self._holds)
        if keep_arm and Source.ARM.value in stopped:
            stopped.remove(Source.ARM.value)
        self._stop_sources(stopped, OPERATOR_TOOK_OVER)
        self.release_estop()

    def _stop_sources(self, stopped: list[str], reason: str) -> None:
        """Stop these sources (their registered stops, in the table's order), and zero
        whatever channel one of them still holds."""
        for source in stopped:
            self.mux.stop(source, reason)
        for channel in self._channels:
            if self._requested(channel).source.value in stopped:
                self._set_channel(channel, 0.0, Source.NONE)

    def _holds(self, source: str, condition: str) -> bool:
        """Whether a `keeps if <condition>` of the mux's table holds now."""
        if condition == "background":
            return self._pad_background
        if condition == "external":
            return self.nav.assist_external
        moving_to = self.arm.controller.moving_to if self.arm is not None else None
        if condition == "a move":
            return moving_to is not None
        if condition == "a jog":
            return moving_to is None
        raise MuxError(f"{self.mux.origin}: the model knows no condition {condition!r}")

    def _zeroer(self, source: Source) -> Callable[[str], None]:
        """A source's stop that zeroes the channels it commands."""

        def zero(_reason: str) -> None:
            for channel in self._channels:
                if self._requested(channel).source is source:
                    self._set_channel(channel, 0.0, Source.NONE)

        return zero

    def _release_held(self, _reason: str) -> None:
        """The hotkeys' stop: every held key is let go (the caller tells the views)."""
        channels = {channel for channel, _ in self._held.values()}
        self._held.clear()
        for channel in channels:
            self._apply_hotkeys(channel)
        self._zeroer(Source.HOTKEY)(_reason)

    def _arm_stop(self, reason: str) -> None:
        """The arm's stop (a move stops for operator input as "operator input")."""
        self._stop_arm("operator input" if reason == OPERATOR_TOOK_OVER else reason)

    def _stop_position(self, _reason: str) -> None:
        """Position control's stop: every target cancelled, its channels zeroed."""
        self.controller.cancel()
        self._sync_targets()
        self._zeroer(Source.POSITION)(_reason)

    def _zero_all(
        self, *, lock: str | None = None, pad_background: bool = False, reason: str = "stopped"
    ) -> None:
        had_keys = bool(self.held_keys)
        self._pad_background = pad_background
        try:
            stopped = (
                self.mux.stopped_by(lock, self._holds) if lock is not None else self.mux.sources
            )
        finally:
            self._pad_background = False
        self._stop_sources(list(stopped), reason)
        self.nav.cancel_override()
        if had_keys:
            self.events.held_changed.emit(self.held_keys)
