"""The controller manager: the control loop on a thread of its own, at a fixed rate.

ros2_control's `ControllerManager::update()` reads every hardware component, updates the active
controllers and writes the hardware, once per period of a real-time loop; ours does the same
for the console model (ocu.console.model), which holds the input arbitration (the latest manual
input wins, automatic sources yield to operator input, locks for e-stop, LINK LOST, focus and
the zones - docs/console.md) and the controllers (position control, synchronized arm moves,
Cartesian jogs, the assisted modes, tracking). One cycle, in this order, under the model's
lock:

1. read: what the hardware component (ocu.core.hardware) reported since the last cycle goes
   into the model (the commands the link sent, then the newest telemetry frame: the joints'
   predictors need both, in order);
2. watch: a GUI thread silent past its limit while motion is commanded stops what the GUI
   feeds (the input mux's "GUI silent" lock: the operator's keys and sliders cannot be
   released through a frozen GUI); a gap in this thread's own cycles longer than the link's
   alive timeout halts everything (the link has zeroed by then);
3. update: the model's control step at this cycle's time (controllers, assisted modes, zones);
4. write: the model's command to the hardware (written only when it changed: the link's own
   safety zeroing stands until the model's command changes), still under the lock; then the
   hardware hears this thread is alive.

A changed command does not wait for the next cycle: `attach` connects the model's
`command_changed`, `estop_requested` and `stream_request_changed` events `direct` to the
hardware, so whichever thread changed the command (this one, the GUI's, the pad's) writes it
at once, under the model's lock.

The GUI posts operator input by calling the model through a `Guarded` handle (ocu.core.guard:
the same lock, held for one call) and paints from what the model's events hand it on the GUI
thread (ocu.console.events.hand_over). Nothing the GUI thread does - painting, a stall, a
garbage collection there - delays a cycle by more than one model call.

Timing is measured: cycles per second, the worst period and the worst cycle time of the last
`TIMING_WINDOW_S`, and overruns (a period longer than `OVERRUN_FACTOR` times the nominal one).
"""

from __future__ import annotations

import argparse
import logging
import os
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

from ocu.console.stall import StallWatch
from ocu.control.arm_timed import TIMED_MOVES
from ocu.priority import current_nice
from ocu.records import CameraRequest, Command

if TYPE_CHECKING:
    from ocu.console.model import ConsoleModel

log = logging.getLogger("ocu.core")

# 50 Hz: measured (bench/bench_core.py), a 100 Hz Python thread beside the GUI's made the key
# path 5x slower at p50 beside two CPU hogs (the GIL); 50 Hz cost nothing there.
DEFAULT_RATE_HZ = 50.0
MIN_RATE_HZ = 5.0
MAX_RATE_HZ = 1000.0
# A period longer than this many nominal periods is an overrun.
OVERRUN_FACTOR = 1.5
TIMING_WINDOW_S = 10.0
JOIN_TIMEOUT_S = 2.0


class Hardware(Protocol):
    """What the manager needs of the robot (ocu.core.hardware.HardwareComponent)."""

    def read(self, model: ConsoleModel) -> None:
        """What the robot reported since the last call, into the model (its lock held)."""

    def write(self, command: Command) -> bool:
        """Command the robot (at once when the command changed); False: refused (read-only)."""

    def emergency_stop(self, reason: str = "operator") -> bool:
        """Zero all motion at once; False: nothing to stop (read-only)."""

    def set_stream_request(self, cameras: Sequence[CameraRequest]) -> bool:
        """Ask for these camera streams; False: refused."""

    def heartbeat(self) -> None:
        """This thread is alive (the link zeroes motion when it stops hearing it)."""


@dataclass(frozen=True)
class ControlTiming:
    """How the control thread keeps its rate (over the last `TIMING_WINDOW_S`)."""

    rate_hz: float  # nominal
    cycles: int  # since start
    measured_hz: float  # cycles in the last second
    worst_period_s: float
    worst_cycle_s: float  # the longest time one cycle took (its wait for the lock included)
    worst_wait_s: float  # the longest a cycle waited for the model's lock (the GUI held it)
    overruns: int  # since start
    nice: int | None = None  # the control thread's nice value (None: not started)
    realtime: bool = False  # it runs under a real-time policy (a core process: SCHED_RR)

    @property
    def text(self) -> str:
        """One line for the status bar and the logs."""
        at = "" if self.nice is None else f" at nice {self.nice}"
        if self.realtime:
            at = " at real-time priority (SCHED_RR)"
        return (
            f"control {self.measured_hz:.0f}/{self.rate_hz:.0f} Hz{at}, worst period "
            f"{1000 * self.worst_period_s:.1f} ms, cycle {1000 * self.worst_cycle_s:.1f} ms "
            f"(waited {1000 * self.worst_wait_s:.1f} ms for the lock), "
            f"{self.overruns} overrun(s)"
        )


class ControllerManager:
    """Runs a ConsoleModel's control cycle on the "ocu-control" thread (see the module doc)."""

    def __init__(
        self,
        model: ConsoleModel,
        lock: threading.RLock,
        *,
        hardware: Hardware | None = None,
        rate_hz: float = DEFAULT_RATE_HZ,
        alive_timeout_s: float = 0.5,
        gui_timeout_s: float | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if not MIN_RATE_HZ <= rate_hz <= MAX_RATE_HZ:
            raise ValueError(
                f"control rate must be {MIN_RATE_HZ:g}-{MAX_RATE_HZ:g} Hz, got {rate_hz!r}"
            )
        self.model = model
        self.lock = lock
        self.hardware: Hardware | None = None
        self.rate_hz = rate_hz
        self.period_s = 1.0 / rate_hz
        self.gui_timeout_s = gui_timeout_s
        self.clock = clock
        self._stall = StallWatch(max(alive_timeout_s, self.period_s))
        self._gui_alive_at: float | None = None
        self._gui_moving = False
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._timing_lock = threading.Lock()
        # (at, period, cycle, wait for the lock)
        self._periods: deque[tuple[float, float, float, float]] = deque()
        self._cycles = 0
        self._overruns = 0
        self.error: BaseException | None = None
        self.failures = 0  # cycles that raised (logged; the thread goes on)
        self._last_wait_s = 0.0  # how long the last cycle waited for the model's lock
        self._nice: int | None = None  # the thread's, read when it starts (ocu.priority)
        self._realtime = False
        if hardware is not None:
            self.attach(hardware)

    # ---- the hardware ------------------------------------------------------------------------

    def attach(self, hardware: Hardware) -> None:
        """Read and write `hardware` from now on (its events subscribed before it starts)."""
        self.detach()
        events = self.model.events
        with self.lock:
            self.hardware = hardware
            if self.model.arm is not None:
                # A robot that runs a position command with a duration gets the arm's moves
                # as one such command (ocu.control.arm_timed).
                capabilities: frozenset[str] = getattr(hardware, "capabilities", frozenset())
                self.model.arm.controller.timed_moves = TIMED_MOVES in capabilities
            events.command_changed.connect(self._write_now, direct=True)
            events.estop_requested.connect(self._estop_now, direct=True)
            events.stream_request_changed.connect(self._streams_now, direct=True)
            hardware.write(self.model.command())
            hardware.set_stream_request(self.model.stream_request)

    def detach(self) -> None:
        """Stop reading and writing the current hardware (idempotent)."""
        events = self.model.events
        with self.lock:
            hardware, self.hardware = self.hardware, None
            if hardware is None:
                return
            events.command_changed.disconnect(self._write_now)
            events.estop_requested.disconnect(self._estop_now)
            events.stream_request_changed.disconnect(self._streams_now)

    def _write_now(self) -> None:
        # The thread that changed the command, the model's lock held: at once, no cycle waited.
        hardware = self.hardware
        if hardware is not None:
            hardware.write(self.model.command())

    def _estop_now(self, reason: str) -> None:
        hardware = self.hardware
        if hardware is not None:
            hardware.emergency_stop(reason)

    def _streams_now(self, cameras: tuple[CameraRequest, ...]) -> None:
        hardware = self.hardware
        if hardware is not None:
            hardware.set_stream_request(cameras)

    # ---- the thread --------------------------------------------------------------------------

    def start(self) -> None:
        """Start the control thread (idempotent)."""
        if self._thread is not None:
            return
        self._thread = threading.Thread(target=self._run, name="ocu-control", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop the thread after its current cycle (idempotent)."""
        self._stop.set()
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(JOIN_TIMEOUT_S)

    @property
    def running(self) -> bool:
        """Whether the control thread runs."""
        return self._thread is not None and self._thread.is_alive()

    def _run(self) -> None:
        self._nice = current_nice()
        self._realtime = os.sched_getscheduler(0) in (os.SCHED_RR, os.SCHED_FIFO)
        next_at = self.clock()
        last_at: float | None = None
        try:
            while not self._stop.is_set():
                started = self.clock()
                try:
                    self.cycle()
                except Exception:  # one bad event or step must not end the robot's control
                    self.failures += 1
                    log.exception("control cycle failed")
                ended = self.clock()
                if last_at is not None:
                    self._measure(started, started - last_at, ended - started, self._last_wait_s)
                last_at = started
                next_at += self.period_s
                if next_at < ended:
                    # Late by more than a period: start again from now, never catch up in a
                    # burst (a burst of control steps would act on the same readings).
                    next_at = ended + self.period_s
                self._stop.wait(max(0.0, next_at - self.clock()))
        except BaseException as err:  # the thread's end must be known: the link zeroes then
            self.error = err
            log.exception("the control thread failed; the link zeroes motion without it")
            raise

    # ---- one cycle -----------------------------------------------------------------------------

    def cycle(self, now: float | None = None) -> None:
        """One control cycle (the thread's; tests may call it directly)."""
        given = now
        model = self.model
        asked = time.perf_counter()
        with self.lock:
            self._last_wait_s = time.perf_counter() - asked
            # The time the commands of this cycle go out at: after the wait for the lock
            # (the GUI thread held it), not before.
            now = self.clock() if given is None else given
            hardware = self.hardware
            if hardware is not None:
                hardware.read(model)
            self._stall.alive(now, model.is_moving)
            stalled_s = self._stall.take_stall()
            if stalled_s is not None:
                # This thread was silent long enough for the link to zero what it sent.
                model.halt(f"control thread stalled for {stalled_s:.2f} s")
            gui_silent_s = self._gui_silent(now)
            if gui_silent_s is not None:
                self._gui_moving = False
                model.halt(f"GUI thread silent for {gui_silent_s:.2f} s", lock="GUI silent")
            model.update(now)
            if hardware is not None:
                hardware.write(model.command())
        if hardware is not None:
            hardware.heartbeat()

    # ---- the GUI's sign of life ------------------------------------------------------------------

    def gui_alive(self) -> None:
        """The GUI thread runs (its heartbeat timer, and each call it makes into the model)."""
        with self.lock:
            self._gui_moving = bool(self.model.is_moving)
            self._gui_alive_at = self.clock()

    def _gui_silent(self, now: float) -> float | None:
        limit = self.gui_timeout_s
        alive_at = self._gui_alive_at
        if limit is None or alive_at is None or not self._gui_moving:
            return None
        silent = now - alive_at
        return silent if silent > limit else None

    # ---- timing --------------------------------------------------------------------------------

    def _measure(self, at: float, period: float, cycle: float, wait: float) -> None:
        with self._timing_lock:
            self._cycles += 1
            if period > OVERRUN_FACTOR * self.period_s:
                self._overruns += 1
            periods = self._periods
            periods.append((at, period, cycle, wait))
            while periods and periods[0][0] < at - TIMING_WINDOW_S:
                periods.popleft()

    def timing(self) -> ControlTiming:
        """The rate kept, the worst period and cycle time, overruns (any thread)."""
        now = self.clock()
        with self._timing_lock:
            periods = list(self._periods)
            cycles, overruns = self._cycles, self._overruns
        recent = [p for p in periods if p[0] >= now - 1.0]
        return ControlTiming(
            rate_hz=self.rate_hz,
            cycles=cycles,
            measured_hz=float(len(recent)),
            worst_period_s=max((p[1] for p in periods), default=0.0),
            worst_cycle_s=max((p[2] for p in periods), default=0.0),
            worst_wait_s=max((p[3] for p in periods), default=0.0),
            overruns=overruns,
            nice=self._nice,
            realtime=self._realtime,
        )


def control_rate(text: str) -> float:
    """--control-hz: a rate the control thread can keep, in Hz."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not MIN_RATE_HZ <= value <= MAX_RATE_HZ:
        raise argparse.ArgumentTypeError(f"{text} Hz is outside {MIN_RATE_HZ:g}-{MAX_RATE_HZ:g} Hz")
    return value
