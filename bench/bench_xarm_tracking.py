"""Seed 003's tracking on the xArm: the tracking error while the object moves, ours against the
seed's plain PID, with 0 and 30 ms of added link delay.

    python bench/bench_xarm_tracking.py                    # 0 and 30 ms, 12 s per run
    python bench/bench_xarm_tracking.py --latency-ms 30 --seconds 20 --trials 3

The real console model and control core (ocu.headless) over the real XarmLink (pyserial) to
the real xArm simulator on a pseudo-terminal (seed 003's servo model: ξ 0.18, ωn 5.83 rad/s;
`--latency-ms` each way: the added delay); the camera is the scene camera on the simulated
gripper (ocu.sim.xarm_camera: the picture is drawn from the simulated shafts), read on its
own thread by CameraCapture as a USB camera is, fed to the model's tracking as the Video dock
feeds it (tests/console/xarm_camera_rig.py). The object, a 40 mm red disc 150 mm ahead of the
camera, stands still for 1.5 s, is clicked, then moves: ±40 mm across, ±20 mm in depth (period
6 s) and ±20 mm up and down (period 12 s).

The error is ground truth, not the tracker's opinion: the object's true position in the
camera's frame (the simulated shafts through the URDF) every 20 ms: its distance from the
picture's centre in pixels (640x480, 70° across), from the optical axis in mm, and the distance
error (mm: how far the depth is from the clicked distance), RMS and p95 over the motion
(its first second left out: the start).

Ours (ocu.control.reach_tracking): the targets placed with the shafts the commands give (the
servo model), the error against the setpoints sent (a Smith predictor) with gains for the dead
time (60° of phase, at most 4 /s), the targets' rates fed forward. Baseline, same run: the
seed's plain PID, the last frame's errors with the fixed gains that give its 29.5° phase
margin (ReachOptions.baseline()).

This machine may be shared: when the console stops the tracking for a stall (its control or
link thread starved past its watchdog, which is right to stop), the object is clicked again
where it is, the second after that is left out and the run made as much longer; the stalls
are counted and printed.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ocu.control.reach_tracking import ReachOptions
from ocu.priority import DEFAULT_NICE, raise_priority
from ocu.sim.xarm_camera import OBJECT_AHEAD, Point
from tests.console.xarm_camera_rig import camera_rig

STILL_S = 1.5
SETTLE_S = 1.0
SAMPLE_S = 0.02
AMPLITUDE_M = (0.02, 0.04, 0.02)
PERIOD_S = 6.0


def moving_object(start: float) -> Callable[[float], Point]:
    """Still until `start`, then the motion of the module docstring."""

    def at(now: float) -> Point:
        if now < start:
            return OBJECT_AHEAD
        phase = math.tau * (now - start) / PERIOD_S
        return (
            OBJECT_AHEAD[0] + AMPLITUDE_M[0] * math.sin(phase),
            OBJECT_AHEAD[1] + AMPLITUDE_M[1] * math.sin(phase),
            OBJECT_AHEAD[2] + AMPLITUDE_M[2] * math.sin(phase / 2.0),
        )

    return at


@dataclass(frozen=True)
class Run:
    pixels_rms: float
    pixels_p95: float
    axis_mm_rms: float
    depth_mm_rms: float
    kp: float
    frames: int
    stalls: int


def rms(values: list[float]) -> float:
    return math.sqrt(sum(v * v for v in values) / len(values))


def p95(values: list[float]) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(0.95 * (len(ordered) - 1)))]


def one_run(latency_ms: float, options: ReachOptions | None, seconds: float) -> Run:
    """One run: click, move the object, sample the ground truth (module docstring)."""
    holder = {"start": time.monotonic() + 3600.0}  # still until clicked

    def at(now: float) -> Point:
        return moving_object(holder["start"])(now)

    rig_iter = camera_rig(at, latency_ms=latency_ms, options=options)
    rig = next(rig_iter)
    try:
        rig.latest()
        threading.Event().wait(STILL_S)  # the still object, the servos at rest
        rig.start_tracking()
        clicked_depth = rig.error()[2]
        holder["start"] = time.monotonic()
        pixels: list[float] = []
        axis: list[float] = []
        depth: list[float] = []
        tick = threading.Event()
        counted_from = holder["start"] + SETTLE_S
        end = holder["start"] + seconds
        clicks = 1
        while time.monotonic() < end:
            tick.wait(SAMPLE_S)
            if rig.headless.call(lambda: rig.model.tracking) is None:
                # The console stopped it (a stall): clicked again where the object is now,
                # the second after left out, the run as much longer.
                clicks += 1
                rig.start_tracking()
                counted_from = time.monotonic() + SETTLE_S
                end += SETTLE_S
                continue
            if time.monotonic() < counted_from:
                continue
            error_px, off_axis_m, depth_m = rig.error()
            pixels.append(error_px)
            axis.append(off_axis_m * 1000.0)
            depth.append((depth_m - clicked_depth) * 1000.0)
        session = rig.headless.call(lambda: rig.model.tracking_session)
        gains = getattr(getattr(session, "reach", None), "gains", None)
        frames = session.frames if session is not None else 0
        return Run(
            rms(pixels), p95(pixels), rms(axis), rms(depth),
            gains.kp if gains is not None else 0.0, frames, clicks - 1,
        )  # fmt: skip
    finally:
        next(rig_iter, None)


def measure(latency_ms: float, options: ReachOptions | None, args: argparse.Namespace) -> Run:
    runs = [one_run(latency_ms, options, args.seconds) for _ in range(args.trials)]
    return Run(
        statistics.median(r.pixels_rms for r in runs),
        statistics.median(r.pixels_p95 for r in runs),
        statistics.median(r.axis_mm_rms for r in runs),
        statistics.median(r.depth_mm_rms for r in runs),
        runs[0].kp,
        round(statistics.median(r.frames for r in runs)),
        sum(r.stalls for r in runs),
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n", 1)[0])
    parser.add_argument("--latency-ms", type=float, action="append", help="each way (0, 30)")
    parser.add_argument("--seconds", type=float, default=12.0)
    parser.add_argument("--trials", type=int, default=1, help="runs per case (median)")
    args = parser.parse_args()
    print("priority:", raise_priority(DEFAULT_NICE).text)  # as the console asks for itself
    latencies = args.latency_ms or [0.0, 30.0]
    print(
        f"object ±{AMPLITUDE_M[1] * 1000:.0f} mm across, ±{AMPLITUDE_M[0] * 1000:.0f} mm deep, "
        f"±{AMPLITUDE_M[2] * 1000:.0f} mm up; {args.seconds:g} s per run, "
        f"{args.trials} run(s) per case"
    )
    header = "delay  controller  Kp 1/s  px RMS  px p95  axis mm RMS  depth mm RMS  frames  stalls"
    print(header)
    results = {}
    for latency in latencies:
        for name, options in (("ours", None), ("seed PID", ReachOptions.baseline())):
            run = measure(latency, options, args)
            results[latency, name] = run
            print(
                f"{latency:4.0f}ms  {name:10s}  {run.kp:6.2f}  {run.pixels_rms:6.1f}  "
                f"{run.pixels_p95:6.1f}  {run.axis_mm_rms:11.1f}  {run.depth_mm_rms:12.1f}  "
                f"{run.frames:6d}  {run.stalls:6d}"
            )
    for latency in latencies:
        ours, seed = results[latency, "ours"], results[latency, "seed PID"]
        print(
            f"{latency:4.0f}ms  seed PID / ours: px RMS {seed.pixels_rms / ours.pixels_rms:.2f}x, "
            f"axis {seed.axis_mm_rms / ours.axis_mm_rms:.2f}x, "
            f"depth {seed.depth_mm_rms / ours.depth_mm_rms:.2f}x"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
