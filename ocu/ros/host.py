"""`ocu-ros` as a host of the console's control core: what joins the ROS bridge to the model.

The node runs a `ConsoleModel` under a `HeadlessConsole` (ocu.headless: the "ocu-control"
thread reads the robot, runs the model's update - the input mux, the zones, the path mode -
writes the robot and beats the link's heartbeat), as the window does. The bridge's
velocities go into the model as `Source.ROS` through `ModelSink`; /follow_path starts the
model's path mode (`follow_path`), and a cmd_vel ends it (`end_path`).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Mapping

from ocu.console.channels import Source
from ocu.console.model import ConsoleModel
from ocu.control.arm_timed import TIMED_MOVES
from ocu.headless import HeadlessConsole
from ocu.records import CommandError
from ocu.ros.bridge import BridgeCore

log = logging.getLogger("ocu.ros")

# How often the halt thread looks at the bridge thread's steps.
WATCH_PERIOD_S = 0.05
CLOSE_TIMEOUT_S = 2.0


def live_goal_core(model: ConsoleModel) -> BridgeCore:
    """The goal core of a live client's arm topics (ocu.live.goals): the bridge's joint goals,
    arm moves and jog, with the console's stored poses."""
    arm = model.arm
    path = arm.poses.path if arm is not None else None
    return BridgeCore(model.profile, arm_poses_path=path, source="live client")


class ModelSink:
    """The bridge's velocities into the console model (`Source.ROS`), under its lock.

    The model stops ROS by its own rules too (the input mux, ocu/control/mux.md: LINK LOST,
    the link's safety stops, a stalled control thread): the stop registered here zeroes ROS's
    channels in the model at once and has the bridge drop its goals (`BridgeCore.halt`), so
    nothing ROS started resumes by itself; the next ROS command is obeyed. The core is halted
    from a thread of its own ("ocu-ros-halt"): the stop runs under the model's lock, and the
    bridge calls this sink under the core's lock.

    The same thread watches the bridge thread (`stepped`, each of its steps), which enforces
    the cmd_vel timeout: silent past `silent_after_s`, what ROS moves stops and ROS moves
    nothing until it steps again (what the link's heartbeat did when the bridge thread beat
    it; the heartbeat is now the control thread's).
    """

    def __init__(
        self,
        console: HeadlessConsole,
        *,
        silent_after_s: float,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.console = console
        self.model = console.model
        self.silent_after_s = silent_after_s
        self.clock = clock
        self.core: BridgeCore | None = None
        self._lock = threading.Lock()
        self._wake = threading.Condition(self._lock)
        self._pending: str | None = None  # a stop the bridge's core has not heard yet
        self._closed = False
        self._stepped_at = clock()
        self._silent = False
        self._thread = threading.Thread(target=self._run, name="ocu-ros-halt", daemon=True)
        self.model.mux.register(Source.ROS.value, self._ros_stopped)

    def start(self, core: BridgeCore) -> None:
        """Halt this core when the model stops ROS; start watching the bridge thread."""
        self.core = core
        self.stepped()
        self._thread.start()

    def close(self) -> None:
        """Stop the halt thread (idempotent)."""
        with self._lock:
            self._closed = True
            self._wake.notify_all()
        if self._thread.is_alive():
            self._thread.join(CLOSE_TIMEOUT_S)

    def stepped(self) -> None:
        """The bridge thread ran a step (RosBridge's `on_step`)."""
        with self._lock:
            self._stepped_at = self.clock()
            back = self._silent
            self._silent = False
        if back:
            log.info("the ROS bridge thread runs again: ROS commands are obeyed")

    @property
    def timed_moves(self) -> bool:
        """Whether the hardware runs a position command with a duration (the arm's moves go
        as one: ocu.control.arm_timed)."""
        return TIMED_MOVES in self.console.hardware.capabilities

    def set_ends(self, until: Mapping[str, float], goals: Mapping[str, float]) -> None:
        """When the bridge's channels end by themselves and their goals (its arm's timed
        move), for the velocities that follow."""
        self.console.call(lambda: self.model.set_source_ends(Source.ROS, until, goals))

    def set_velocities(self, **velocities: float) -> None:
        """The bridge's command (its core's lock held): into the model."""
        with self._lock:
            if self._pending is not None or self._silent:
                # The model stopped ROS and the core has not dropped its goals yet (a goal's
                # next step must not take the channels back meanwhile), or the bridge thread
                # is silent (nothing would enforce the cmd_vel timeout).
                velocities = dict.fromkeys(velocities, 0.0)
        try:
            self.console.call(lambda: self.model.set_external_velocities(velocities))
        except CommandError as err:
            log.warning("ROS command refused: %s", err)

    def _ros_stopped(self, reason: str) -> None:
        # The mux's stop of ROS, the model's lock held: zero now, the core on the halt thread.
        self.model.clear_external()
        self._halt_core(reason or "stopped")

    def _halt_core(self, reason: str) -> None:
        with self._lock:
            self._pending = reason
            self._wake.notify_all()

    def _run(self) -> None:
        while True:
            with self._lock:
                self._wake.wait_for(
                    lambda: self._closed or self._pending is not None, WATCH_PERIOD_S
                )
                if self._closed:
                    return
                reason = self._pending
            if reason is not None:
                core = self.core
                if core is not None:
                    core.halt(reason)
                with self._lock:
                    if self._pending == reason:
                        self._pending = None
            self._watch()

    def _watch(self) -> None:
        with self._lock:
            silent_s = self.clock() - self._stepped_at
            if self._silent or silent_s <= self.silent_after_s:
                return
            self._silent = True
        self.console.call(self.model.clear_external)
        reason = f"the ROS bridge thread silent for {silent_s:.2f} s"
        log.error("%s: what ROS moves is stopped until it runs again", reason)
        self._halt_core(reason)


def follow_path(
    console: HeadlessConsole, core: BridgeCore, points: list[tuple[float, float]]
) -> None:
    """/follow_path: the model's path mode (Source.ASSIST), started as a planner's."""
    refusal = core.refusal()
    if refusal:
        log.error("follow_path ignored: %s", refusal)
        return
    try:
        console.call(lambda: console.model.start_path(points, external=True))
    except CommandError as err:
        log.error("follow_path refused: %s", err)
        return
    log.info("follow_path: %d poses in odom, path mode started", len(points))


def end_path(console: HeadlessConsole) -> None:
    """A cmd_vel ends a path ROS gave (the node's only path mode)."""
    model = console.model

    def end() -> bool:
        if model.assist_mode != "path":
            return False
        model.stop_assist("cmd_vel took over")
        return True

    if console.call(end):
        log.info("follow_path stopped: cmd_vel took over")
