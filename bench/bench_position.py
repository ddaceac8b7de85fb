"""Position-control step responses in the simulator: ours against the paper's controller.

For 30° and 90° steps of the shoulder at 1 Hz and 10 Hz telemetry, both controllers drive the
real simulator over UDP; the simulator's ground truth gives overshoot, final error and the
settle time (from the step until the joint stays within 0.5° of the target).

    .venv/bin/python bench/bench_position.py
"""

from __future__ import annotations

import argparse
import math

from ocu.control.commands import VelocityLimits
from ocu.control.position import ConstantSpeedController, PositionController
from ocu.control.runner import PositionRunner
from ocu.link.core import LinkCore, LinkListener, TelemetryFrame
from ocu.profile import load_profile
from ocu.sim.simulator import RobotSimulator, StateRecorder

JOINT = "shoulder"
SETTLE_BAND_DEG = 0.5


class Forward(LinkListener):
    def __init__(self, runner: PositionRunner) -> None:
        self.runner = runner

    def telemetry_received(self, frame: TelemetryFrame) -> None:
        self.runner.on_readings(frame.readings, frame.received_at)


def step_response(
    kind: str, telemetry_hz: float, step_deg: float, window_s: float
) -> dict[str, float]:
    """Run one step and measure it against the simulator's ground truth."""
    profile = load_profile()
    sim = RobotSimulator(profile, telemetry_hz=telemetry_hz, video_fps=0.0)
    sim.start()
    limits = VelocityLimits(profile)
    speed = limits.get(profile.motors[JOINT].channel or JOINT)
    controller: PositionController = (
        PositionController(profile, limits)
        if kind == "ours"
        else ConstantSpeedController(profile, limits, speed)
    )
    link = LinkCore(profile, sim.address, gui_alive_timeout_s=None)
    runner = PositionRunner(controller, link)
    link.listener = Forward(runner)
    link.start()
    recorder = StateRecorder(sim)
    try:
        sim.wait_until(lambda s: s.telemetry_sent >= 1, 5.0)
        target = math.radians(step_deg)
        start_s = sim.state().time_s
        controller.set_target(JOINT, target)
        # The paper's controller never declares itself done; both are observed for the same
        # window after the step (ours keeps watching after it finishes).
        runner.run(timeout_s=window_s, settle_s=window_s)
    finally:
        recorder.stop()
        link.shutdown()
        sim.stop()
    trace = [
        (state.time_s - start_s, math.degrees(state.joints_rad[JOINT]))
        for state in recorder.samples
        if state.time_s >= start_s
    ]
    final = trace[-1][1]
    overshoot = max(0.0, max(a for _, a in trace) - step_deg)
    settle = math.nan
    for t, a in reversed(trace):
        if abs(a - step_deg) > SETTLE_BAND_DEG:
            settle = t
            break
    else:
        settle = 0.0
    if abs(final - step_deg) > SETTLE_BAND_DEG:
        settle = math.inf
    return {"final_error": abs(final - step_deg), "overshoot": overshoot, "settle": settle}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--window", type=float, default=15.0, help="seconds observed per step")
    args = parser.parse_args()
    print(f"joint {JOINT}, observed {args.window:.0f} s per step; settle band ±{SETTLE_BAND_DEG}°")
    print(
        f"{'telemetry':>9} {'step':>5} {'controller':>14} {'final err °':>11} "
        f"{'overshoot °':>11} {'settle s':>9}"
    )
    for telemetry_hz in (1.0, 10.0):
        for step_deg in (30.0, 90.0):
            results = {}
            for kind in ("paper", "ours"):
                r = step_response(kind, telemetry_hz, step_deg, args.window)
                results[kind] = r
                settle = "never" if math.isinf(r["settle"]) else f"{r['settle']:.2f}"
                print(
                    f"{telemetry_hz:>7.0f}Hz {step_deg:>4.0f}° {kind:>14} "
                    f"{r['final_error']:>11.2f} {r['overshoot']:>11.2f} {settle:>9}"
                )
            paper, ours = results["paper"]["settle"], results["ours"]["settle"]
            ratio = "∞" if math.isinf(paper) else f"{paper / ours:.1f}x"
            print(f"{'':>16} settle time paper/ours: {ratio}")


if __name__ == "__main__":
    main()
