"""Position-control step responses in the simulator, under the field's link conditions.

Three controllers drive the real simulator over UDP in the same run:

- ours: the delay-aware controller (ocu.control.position: Smith predictor, measured delay);
- today: the controller on main before the field-control issue (bench/baseline_position.py:
  predicts between packets, resets the prediction to each reading);
- paper: the paper's constant-speed controller (ConstantSpeedController).

Steps: the shoulder by 30° and by 90°, and waist + shoulder + elbow together. Link: one-way
latency 0 / 100 / 200 ms x telemetry 1 / 10 Hz, each clean, with 10 % loss each way, and with
±0.5° reading noise. The simulator's ground truth gives overshoot (beyond the target, largest
over the joints), final error, settle time (from the step until every joint stays within
±0.5°) and the messages judged against it: a false "reached" (the joint was more than 0.5°
off when the controller said so) and a false "stall" (the simulator's joints always move as
commanded). Runs go in parallel worker processes (`--jobs`): each run is a simulator, a link
and a 50 Hz control loop, a few percent of a core.

    .venv/bin/python bench/bench_position.py            # the whole grid, ~6 min
    .venv/bin/python bench/bench_position.py --quick    # shoulder 30° only
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import Any

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from baseline_position import ConstantSpeedController, ResetPredictionController

from ocu.control.commands import VelocityLimits
from ocu.control.position import PositionController
from ocu.link.live import UdpLink
from ocu.link.runner import Controller, PositionRunner
from ocu.profile import load_profile
from ocu.sim.faults import FaultConfig
from ocu.sim.simulator import RobotSimulator, StateRecorder

BAND_DEG = 0.5
STEPS: dict[str, dict[str, float]] = {
    "shoulder 30°": {"shoulder": 30.0},
    "shoulder 90°": {"shoulder": 90.0},
    "waist+shoulder+elbow": {"waist": 60.0, "shoulder": 45.0, "elbow": -50.0},
}
LATENCIES_MS = (0.0, 100.0, 200.0)
RATES_HZ = (1.0, 10.0)
CONDITIONS = ("clean", "loss 10%", "noise ±0.5°")
CONTROLLERS = ("ours", "today", "paper")
OBSERVE_AFTER_S = 2.0


@dataclass(frozen=True)
class Case:
    step: str
    latency_ms: float
    rate_hz: float
    condition: str
    controller: str
    window_s: float
    seed: int


def run_case(case: Case) -> dict[str, Any]:
    """One step response against the simulator's ground truth."""
    profile = load_profile()
    faults = FaultConfig(
        latency_ms=case.latency_ms, loss=0.1 if case.condition.startswith("loss") else 0.0
    )
    noise = 0.5 if case.condition.startswith("noise") else 0.0
    targets = STEPS[case.step]
    sim = RobotSimulator(
        profile,
        telemetry_hz=case.rate_hz,
        video_fps=0.0,
        faults=faults,
        seed=case.seed,
        noise_deg=noise,
    )
    sim.start()
    limits = VelocityLimits(profile)
    controller: Controller
    if case.controller == "ours":
        controller = PositionController(profile, limits)
    elif case.controller == "today":
        controller = ResetPredictionController(profile, limits)
    else:
        speed = min(limits.get(profile.motors[j].channel or j) for j in targets)
        controller = ConstantSpeedController(profile, limits, speed)
    link = UdpLink(profile, sim.address, gui_alive_timeout_s=None)
    runner = PositionRunner(controller, link)
    link.subscribe(runner.on_link_event)
    link.start()
    recorder = StateRecorder(sim)
    try:
        sim.wait_until(lambda s: s.telemetry_sent >= 2, 10.0)
        start_mono = link.clock()
        start_sim = sim.state().time_s
        for joint, deg in targets.items():
            controller.set_target(joint, math.radians(deg))
        # Ours and today's finish by themselves (then watched a little longer); the paper's
        # controller never declares itself done and is watched for the whole window.
        result = runner.run(timeout_s=case.window_s, settle_s=OBSERVE_AFTER_S)
    finally:
        recorder.stop()
        link.shutdown()
        sim.stop()
    samples = [s for s in recorder.samples if s.time_s >= start_sim]
    overshoot = final_error = settle = 0.0
    for joint, deg in targets.items():
        sign = math.copysign(1.0, deg)  # every step starts at 0°
        trace = [(s.time_s - start_sim, math.degrees(s.joints_rad[joint])) for s in samples]
        overshoot = max(overshoot, 0.0, *(sign * (a - deg) for _, a in trace))
        final = abs(trace[-1][1] - deg)
        final_error = max(final_error, final)
        joint_settle = 0.0
        for t, a in reversed(trace):
            if abs(a - deg) > BAND_DEG:
                joint_settle = t
                break
        settle = max(settle, math.inf if final > BAND_DEG else joint_settle)
    false_reached = false_stall = 0
    offset = start_sim - start_mono  # link clock and simulator clock are both monotonic
    for at, message in result.events:
        joint = message.split(":")[0]
        if "does not move as commanded" in message:
            false_stall += 1
        if "reached" in message and joint in targets:
            moment = at + offset
            state = min(samples, key=lambda s: abs(s.time_s - moment))
            if abs(math.degrees(state.joints_rad[joint]) - targets[joint]) > BAND_DEG:
                false_reached += 1
    return {
        "case": case,
        "overshoot": overshoot,
        "final_error": final_error,
        "settle": settle,
        "false_reached": false_reached,
        "false_stall": false_stall,
        "messages": result.messages,
    }


def window_for(step: str) -> float:
    return 14.0 if step == "shoulder 30°" else 22.0


def fmt_settle(value: float) -> str:
    return "never" if math.isinf(value) else f"{value:.2f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--jobs", type=int, default=6, help="parallel runs")
    parser.add_argument("--quick", action="store_true", help="the shoulder 30° step only")
    parser.add_argument("--seed", type=int, default=11)
    args = parser.parse_args()
    steps = ["shoulder 30°"] if args.quick else list(STEPS)
    cases = [
        Case(step, latency, rate, condition, controller, window_for(step), args.seed)
        for step in steps
        for latency in LATENCIES_MS
        for rate in RATES_HZ
        for condition in CONDITIONS
        for controller in CONTROLLERS
    ]
    print(
        f"{len(cases)} step responses, {args.jobs} at a time; band ±{BAND_DEG}°; "
        f"settle 'never' = not within the band at the end of the window"
    )
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        results = list(pool.map(run_case, cases))
    by_key = {
        (r["case"].step, r["case"].latency_ms, r["case"].rate_hz, r["case"].condition,
         r["case"].controller): r
        for r in results
    }  # fmt: skip
    header = (
        f"{'step':<21} {'lat ms':>6} {'tlm':>5} {'condition':<12} {'ctrl':<6} "
        f"{'overshoot°':>10} {'final°':>7} {'settle s':>8} {'false reached':>13} "
        f"{'false stall':>11}"
    )
    print(header)
    print("-" * len(header))
    failures: list[str] = []
    for step in steps:
        for latency in LATENCIES_MS:
            for rate in RATES_HZ:
                for condition in CONDITIONS:
                    for controller in CONTROLLERS:
                        r = by_key[(step, latency, rate, condition, controller)]
                        print(
                            f"{step:<21} {latency:>6.0f} {rate:>3.0f}Hz {condition:<12} "
                            f"{controller:<6} {r['overshoot']:>10.2f} {r['final_error']:>7.2f} "
                            f"{fmt_settle(r['settle']):>8} {r['false_reached']:>13} "
                            f"{r['false_stall']:>11}"
                        )
                    ours = by_key[(step, latency, rate, condition, "ours")]
                    where = f"{step}, {latency:.0f} ms, {rate:.0f} Hz, {condition}"
                    if ours["overshoot"] > 1.0:
                        failures.append(f"{where}: overshoot {ours['overshoot']:.2f}°")
                    if ours["final_error"] > BAND_DEG:
                        failures.append(f"{where}: final error {ours['final_error']:.2f}°")
                    if ours["false_reached"] or ours["false_stall"]:
                        failures.append(f"{where}: false reached/stall {ours['messages']}")
                    if latency == LATENCIES_MS[-1]:
                        base = by_key[(step, 0.0, rate, condition, "ours")]["settle"]
                        if ours["settle"] > 2.0 * base:
                            failures.append(
                                f"{where}: settle {fmt_settle(ours['settle'])} s > 2x the "
                                f"zero-latency {fmt_settle(base)} s"
                            )
    print()
    print("ours, the targets: overshoot <= 1°, final error <= 0.5°, no false reached or stall,")
    print("settle at 200 ms within 2x of the zero-latency settle:")
    if failures:
        for failure in failures:
            print(f"  MISSED {failure}")
    else:
        print("  all met in every cell")
    for name in ("today", "paper"):
        rows = [r for r in results if r["case"].controller == name]
        over = sum(r["overshoot"] > 1.0 for r in rows)
        err = sum(r["final_error"] > BAND_DEG for r in rows)
        false = sum(bool(r["false_reached"] or r["false_stall"]) for r in rows)
        print(
            f"{name}: {over}/{len(rows)} cells overshoot > 1°, {err} end > 0.5° off, "
            f"{false} with a false reached or stall"
        )


if __name__ == "__main__":
    main()
