"""The end of a move: stored-pose moves and a 30° position step, reversals and overshoot.

The console model drives the simulator's physics (ocu.sim.physics) behind a delayed link
(tests/console/arm_rig.py: 100 ms each way, 10 Hz telemetry; every command reaches the robot
when the console publishes it, as the link sends a changed command at once). Per move the
simulator's ground truth gives the overshoot past the goal (largest over the joints), the
*reversals* — commands the robot received that drive a joint against its move, counted per
joint and move, with how soon after the plan's end the first came — and how far apart in
time the joints arrived (last motion of each). Moves: F2 stow and F3 ready, four each; the
shoulder 0 → 30° through the position controller.

Control ticks three ways: `steady` (a 50 ms tick on a hand-stepped clock), `late` (the
irregular intervals a loaded console's GUI thread shows, up to 350 ms, hand-stepped), and
`real` (the wall clock: a 50 ms sleep-paced loop; with `--hogs` two CPU-bound processes run
beside it, started and killed by the bench). Each case runs with the controllers of today's
main in the same run (`main`: bench/baseline_arm_moves.py swaps them in) and ours.

    .venv/bin/python bench/bench_arm_moves.py            # steady + late (hand-stepped)
    .venv/bin/python bench/bench_arm_moves.py --real --hogs
"""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from baseline_arm_moves import use_main_controllers

from ocu import hotkeys
from ocu.hotkeys import load_key_map
from ocu.profile import load_profile
from tests.console.arm_rig import Rig

LATENCY_S = 0.1
TELEMETRY_HZ = 10.0
LATE_TICKS_S = (0.05, 0.05, 0.3, 0.05, 0.2, 0.05, 0.05, 0.05, 0.35, 0.1)
MOVES = ("F2", "F3") * 4
STEP_DEG = 30.0


@dataclass
class Moved:
    label: str
    overshoot_deg: float
    reversals: int
    first_reversal_s: float | None  # after the plan's end
    spread_s: float


class Clock:
    """Tick intervals: a fixed pattern on the rig's clock, or the wall clock."""

    def __init__(self, mode: str) -> None:
        self.mode = mode
        self.step = 0
        self.wall = time.monotonic()

    def next_dt(self) -> float:
        if self.mode == "steady":
            return 0.05
        if self.mode == "late":
            self.step += 1
            return LATE_TICKS_S[self.step % len(LATE_TICKS_S)]
        target = self.wall + 0.05
        remaining = target - time.monotonic()
        if remaining > 0:
            time.sleep(remaining)
        now = time.monotonic()
        dt, self.wall = now - self.wall, now
        return dt


def tick(rig: Rig, clock: Clock) -> None:
    rig.t = round(rig.t + clock.next_dt(), 9)
    rig.robot.run_until(rig.t)
    rig.model.update(rig.t)


def measure(
    rig: Rig,
    clock: Clock,
    label: str,
    goal: dict[str, float],
    *,
    plan_end: float,
    active: Callable[[], bool],
) -> Moved:
    profile = rig.profile
    start = dict(rig.robot.joints)
    moving = {
        j: math.copysign(1.0, goal[j] - start[j]) for j in goal if abs(goal[j] - start[j]) > 0.01
    }
    peak = dict.fromkeys(moving, 0.0)
    last = dict.fromkeys(moving, rig.t)
    previous = dict(start)
    sent_before = len(rig.robot.sent)
    while active():
        tick(rig, clock)
        if rig.t > plan_end + 60.0:
            break
        now = rig.robot.joints
        for joint, direction in moving.items():
            peak[joint] = max(peak[joint], (now[joint] - goal[joint]) * direction)
            if abs(now[joint] - previous[joint]) > 1e-5:
                last[joint] = rig.t
        previous = dict(now)
    for _ in range(20):  # the link's last commands land
        tick(rig, clock)
    reversals = 0
    first: float | None = None
    for joint, direction in moving.items():
        channel = profile.motors[joint].channel
        assert channel is not None
        back = [
            at - plan_end
            for at, command in rig.robot.sent[sent_before:]
            if command.velocity(channel) * direction < 0.0
        ]
        if back:
            reversals += 1
            first = back[0] if first is None else min(first, back[0])
    return Moved(
        label,
        math.degrees(max(peak.values(), default=0.0)),
        reversals,
        first,
        max(last.values()) - min(last.values()) if last else 0.0,
    )


def run(mode: str, controllers: str) -> list[Moved]:
    profile = load_profile()
    key_map = load_key_map(profile)
    with tempfile.TemporaryDirectory() as tmp:
        rig = Rig(profile, Path(tmp), latency_s=LATENCY_S, telemetry_hz=TELEMETRY_HZ)
        if controllers == "main":
            use_main_controllers(rig.model)
        clock = Clock(mode)
        arm = rig.arm.controller
        results = []
        for key in MOVES:
            hotkeys.press(rig.model, key_map, key)
            hotkeys.release(rig.model, key_map, key)
            plan = arm.move_plan
            goal = arm.move_goal
            assert plan is not None, rig.messages[-3:]
            assert goal is not None
            results.append(
                measure(
                    rig,
                    clock,
                    key,
                    goal,
                    plan_end=rig.t + plan.duration_s,
                    active=lambda: arm.active,
                )
            )
        # The 30° position step, from the ready pose: the shoulder 55° → 85°.
        shoulder = rig.robot.joints["shoulder"]
        target = shoulder + math.radians(STEP_DEG)
        rig.model.set_target("shoulder", target)
        results.append(
            measure(
                rig,
                clock,
                f"shoulder {STEP_DEG:+.0f}°",
                {"shoulder": target},
                plan_end=rig.t,
                active=lambda: bool(rig.model.controller.targets),
            )
        )
    return results


def summary(results: list[Moved]) -> str:
    moves = [r for r in results if r.label in ("F2", "F3")]
    step = [r for r in results if r.label not in ("F2", "F3")]
    firsts = [r.first_reversal_s for r in moves if r.first_reversal_s is not None]
    first = f", first {min(firsts) * 1000:+.0f} ms after the plan" if firsts else ""
    return (
        f"stored poses: overshoot max {max(r.overshoot_deg for r in moves):.2f}°, "
        f"reversals {sum(r.reversals for r in moves)} in {len(moves)} moves{first}, "
        f"arrival spread max {max(r.spread_s for r in moves):.2f} s | "
        f"30° step: overshoot {step[0].overshoot_deg:.2f}°, reversals {step[0].reversals}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--real", action="store_true", help="the wall clock instead")
    parser.add_argument("--hogs", action="store_true", help="two CPU-bound processes beside")
    args = parser.parse_args()
    modes = ["real"] if args.real else ["steady", "late"]
    hogs: list[subprocess.Popen[bytes]] = []
    if args.hogs:
        hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    try:
        print(f"{LATENCY_S * 1000:.0f} ms each way, {TELEMETRY_HZ:g} Hz telemetry; "
              f"{'two CPU hogs beside' if hogs else 'no extra load'}")  # fmt: skip
        for mode in modes:
            for controllers in ("main", "ours"):
                print(f"{mode:>6} {controllers:<4}: {summary(run(mode, controllers))}")
    finally:
        for hog in hogs:
            hog.kill()
            hog.wait()


if __name__ == "__main__":
    main()
