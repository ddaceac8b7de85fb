"""The xArm 1S's Arm through the console's control core against the xArm simulator (pty).

Ground truth: the simulated servos' shafts (seed 003's second-order model) through the
xArm's URDF. The console's control core (`HeadlessConsole`, `ConsoleModel(xarm_robot_profile)`,
the `xarm-sim` plug-in, control at 50 Hz as the window), from a bent start (base 0°, shoulder
30°, elbow 60°, wrist pitch 40°), with no faults and with the field's (30 ms each way, garbage
before a fifth of the replies, 1 servo unit of Gaussian noise on every reading):

- **Pose goal** x 200, y 80, z 100 mm, pitch -30° (the Arm's preview and accept), three ways:
  `timed` - one CMD_SERVO_MOVE of the four servos with the plan's duration (the hardware's
  "timed_moves", the default); `streamed` - the same plan streamed as short jog moves with the
  console's feedback (timed moves off: how it went before); `one joint at a time` - base,
  shoulder, elbow, wrist pitch one after the other, each its own move. Figures: the true
  tool0's distance from the target and its pitch error once the shafts rest at their
  setpoints; the time from the accept until the console says the goal is reached, and until
  the shafts rest.
- **20 mm Cartesian jog** along -y in the base frame at the default 20 mm/s: the largest
  distance of the true tool0 from the line, and the travel, from the key press until rest.

    nice -n 5 .venv/bin/python bench/bench_xarm.py [--runs 3]   # ~1 min a run, 2 cores
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import statistics
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from ocu.console.arm import ArmConsole, ArmGoal
from ocu.console.model import ConsoleModel
from ocu.hardware.xarm import SimulatedXarm
from ocu.headless import HeadlessConsole
from ocu.kinematics.arm import ToolPose
from ocu.link.xarm import XarmLink
from ocu.profile.xarm import XarmProfile, load_xarm_profile
from ocu.profile.xarm_robot import xarm_robot_profile
from ocu.records import LinkState
from ocu.sim.xarm import XarmSimulator

DEADLINE_S = 30.0
ARM_JOINTS = ("base", "shoulder", "elbow", "wrist_pitch")
START_DEG = {"base": 0.0, "shoulder": 30.0, "elbow": 60.0, "wrist_pitch": 40.0}
TARGET = ToolPose(0.20, 0.08, 0.10, math.radians(-30.0))
FIELD = {"latency_ms": 30.0, "garbage_rate": 0.2, "noise_units": 1.0}
JOG_M = 0.02


def wait_for(check: Callable[[], bool], what: str) -> None:
    deadline = time.monotonic() + DEADLINE_S
    pause = threading.Event()
    while not check():
        if time.monotonic() > deadline:
            raise RuntimeError(f"not {what} within {DEADLINE_S} s")
        pause.wait(0.005)


@dataclass
class Rig:
    arm: XarmProfile
    sim: XarmSimulator
    headless: HeadlessConsole
    console_arm: ArmConsole

    def angles(self) -> np.ndarray:
        positions = self.sim.snapshot().positions
        return np.array(
            [self.arm.angle_rad(self.arm.joint(n), positions[self.arm.joint(n).servo])
             for n in ARM_JOINTS]
        )  # fmt: skip

    def tool(self) -> np.ndarray:
        return self.console_arm.kinematics.tool_pose(self.angles()).position

    def at_rest(self) -> bool:
        snapshot = self.sim.snapshot()
        return all(
            abs(snapshot.velocities[s]) < 0.5
            and abs(snapshot.positions[s] - snapshot.setpoints[s]) < 1.0
            for s in snapshot.positions
        )

    def call(self, function: Callable[[], object]) -> object:
        return self.headless.call(function)

    def fresh(self) -> bool:
        """Every arm joint read within the last 0.1 s (after a stop for stale readings)."""
        position = self.console_arm.controller.position

        def check() -> bool:
            now = self.headless.model.clock()
            return all(
                (at := position.predictors[j].last_received_at) is not None and now - at < 0.1
                for j in ARM_JOINTS
            )

        return self.headless.call(check)


@contextmanager
def rig(faults: dict[str, float], seed: int) -> Iterator[Rig]:
    arm = load_xarm_profile("xarm1s")
    profile = xarm_robot_profile(arm)
    initial = {
        arm.joint(n).servo: arm.raw_units(arm.joint(n), math.radians(d))
        for n, d in START_DEG.items()
    }
    sim = XarmSimulator(arm, initial=initial, seed=seed, **faults)  # type: ignore[arg-type]
    hardware = SimulatedXarm(sim, XarmLink(arm, sim.start(), profile=profile))
    model = ConsoleModel(profile)
    headless = HeadlessConsole(model, hardware, control_period_s=0.02)
    console_arm = model.arm
    assert console_arm is not None, model.arm_error
    headless.start()
    try:
        wait_for(lambda: headless.link.state is LinkState.CONNECTED, "connected")
        wait_for(lambda: headless.call(console_arm.tool_pose) is not None, "tool0 known")
        yield Rig(arm, sim, headless, console_arm)
    finally:
        headless.stop()


def run_move(setup: Rig, start: Callable[[], ArmGoal]) -> tuple[float, float, int]:
    """Start a move; the seconds from the first start until the console says reached, and
    until the shafts rest, and how often the console stopped it itself (a loaded machine's
    stale reading: started again once readings flow, as an operator would)."""
    arm = setup.console_arm
    messages: list[str] = []
    arm.events.message.connect(messages.append, direct=True)
    started = time.monotonic()
    stops = 0
    try:
        for _ in range(4):
            setup.call(start)
            wait_for(lambda: not setup.call(lambda: arm.controller.active), "the move done")
            reached = time.monotonic() - started
            if not any("stopped" in text for text in messages[-1:]):
                break
            stops += 1
            wait_for(setup.fresh, "fresh readings")
        wait_for(setup.at_rest, "the shafts at rest")
        return reached, time.monotonic() - started, stops
    finally:
        arm.events.message.disconnect(messages.append)


def pose_goal(setup: Rig, method: str) -> dict[str, float]:
    arm = setup.console_arm
    if method == "streamed":
        setup.call(lambda: setattr(arm.controller, "timed_moves", False))
    goal = setup.call(lambda: arm.preview_pose(TARGET))
    assert isinstance(goal, ArmGoal)
    if method == "one joint at a time":
        reached = rest = 0.0
        stops = 0
        current = dict(zip(ARM_JOINTS, setup.angles(), strict=True))
        for joint in ARM_JOINTS:
            current[joint] = goal.joints[joint]
            step = dict(current)

            def one(step: dict[str, float] = step, joint: str = joint) -> ArmGoal:
                return arm.move_to_joints(joint, step)

            one_reached, one_rest, one_stops = run_move(setup, one)
            reached, rest = reached + one_reached, rest + one_rest
            stops += one_stops
    else:

        def accept() -> ArmGoal:
            arm.preview_pose(TARGET)
            return arm.accept()

        reached, rest, stops = run_move(setup, accept)
    pose = arm.kinematics.tool_pose(setup.angles())
    return {
        "error_mm": float(np.linalg.norm(pose.position - np.array(TARGET.position))) * 1000,
        "pitch_deg": abs(math.degrees(pose.pitch - TARGET.pitch)),
        "reached_s": reached,
        "rest_s": rest,
        "stops": stops,
    }


def jog(setup: Rig) -> dict[str, float]:
    arm = setup.console_arm
    origin = setup.tool()
    samples: list[np.ndarray] = []
    done = threading.Event()
    stops = 0

    def record() -> None:
        while not done.wait(0.005):
            samples.append(setup.tool())

    recorder = threading.Thread(target=record, name="bench-recorder")
    recorder.start()
    try:
        setup.call(lambda: arm.set_cartesian(True))
        for _ in range(5):
            wait_for(setup.fresh, "fresh readings")
            setup.call(lambda: arm.jog_key_down("right", "y", -1))
            wait_for(
                lambda: (
                    origin[1] - setup.tool()[1] >= JOG_M
                    or not setup.call(lambda: arm.controller.active)
                ),
                "20 mm or a stop",
            )
            setup.call(lambda: arm.jog_key_up("right"))
            if origin[1] - setup.tool()[1] >= JOG_M:
                break
            stops += 1
        wait_for(setup.at_rest, "the shafts at rest")
    finally:
        done.set()
        recorder.join()
    unit = np.array([0.0, -1.0, 0.0])
    worst = travel = 0.0
    for point in samples:
        offset = point - origin
        along = float(offset @ unit)
        travel = max(travel, along)
        worst = max(worst, float(np.linalg.norm(offset - along * unit)))
    return {"deviation_mm": worst * 1000, "travel_mm": travel * 1000, "stops": stops}


def summary(values: list[float]) -> str:
    if len(values) == 1:
        return f"{values[0]:.2f}"
    return f"{statistics.median(values):.2f} ({min(values):.2f}-{max(values):.2f})"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=3)
    args = parser.parse_args()
    logging.basicConfig(level=logging.ERROR)
    for condition, faults in (("no faults", {}), ("field faults", FIELD)):
        print(f"== {condition} ({args.runs} runs; median (min-max))")
        for method in ("timed", "streamed", "one joint at a time"):
            results: dict[str, list[float]] = {}
            for run in range(args.runs):
                with rig(faults, seed=run + 1) as setup:
                    for key, value in pose_goal(setup, method).items():
                        results.setdefault(key, []).append(value)
            print(
                f"  pose goal, {method:<20} error {summary(results['error_mm'])} mm, pitch "
                f"{summary(results['pitch_deg'])}°, reached {summary(results['reached_s'])} s, "
                f"at rest {summary(results['rest_s'])} s; console stops {sum(results['stops']):g}"
            )
        jogs: dict[str, list[float]] = {}
        for run in range(args.runs):
            with rig(faults, seed=run + 1) as setup:
                for key, value in jog(setup).items():
                    jogs.setdefault(key, []).append(value)
        print(
            f"  20 mm jog: off the line {summary(jogs['deviation_mm'])} mm, travelled "
            f"{summary(jogs['travel_mm'])} mm; console stops {sum(jogs['stops']):g}"
        )
        sys.stdout.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main())
