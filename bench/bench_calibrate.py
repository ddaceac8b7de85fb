"""`ocu calibrate --yes` against the simulator playing scrambled robots (issue 14's figures).

For each seed the real simulator (`ocu-sim --scramble SEED`, in-process, on a UDP socket on
127.0.0.1) plays a robot whose axis map, directions, joint scales, ticks per radian and zero
offsets were redrawn; the calibrator talks to it through a real `UdpLink` built on the
engineer profile, as `ocu calibrate --yes` does. Printed per seed: whether the axis map and
directions came out exact, the worst relative error of the joint scales and ticks per radian
(target 2 %), the worst zero offset error, the time to calibrate, and the largest joint
excursion the simulator's physics went through (target < 10°). The baseline in the same run is
the uncalibrated engineer profile against the same truth.

    nice -n 5 .venv/bin/python bench/bench_calibrate.py [--seeds 1 2 3] [--telemetry-hz 20]
        [--field]   # 20 ± 10 ms each way, 5 % loss each way, ±0.2° reading noise
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ocu.calibrate.guard import OnStand, StopSignal
from ocu.calibrate.operator import AutoOperator
from ocu.calibrate.raw import raw_profile
from ocu.calibrate.session import Calibrator
from ocu.calibrate.writer import write_calibrated_profile
from ocu.link.live import UdpLink
from ocu.profile import RobotProfile, load_profile, load_profile_data, parse_profile
from ocu.sim.faults import FaultConfig
from ocu.sim.scramble import scramble_profile_data
from ocu.sim.simulator import RobotSimulator, StateRecorder


@dataclass
class Row:
    """One seed's figures."""

    seed: int
    axes_exact: bool
    signs_exact: bool
    scale_err: float
    ticks_err: float
    zero_err_deg: float
    duration_s: float
    excursion_deg: float
    base_axes_exact: bool
    base_scale_err: float
    base_ticks_err: float
    aborted: str | None


def _errors(found: RobotProfile, truth: RobotProfile) -> tuple[bool, bool, float, float, float]:
    """Axis map exact, signs exact, worst scale error, worst ticks error, worst zero (deg)."""
    axes = all(found.channels[n].axis == c.axis for n, c in truth.channels.items())
    signs = all(found.channels[n].axis_sign == c.axis_sign for n, c in truth.channels.items())
    scale = max(
        abs(found.channels[n].axis_per_unit / c.axis_per_unit - 1)
        for n, c in truth.channels.items()
        if truth.motor_for_channel(n) is not None
    )
    ticks = 0.0
    zero_deg = 0.0
    for name, motor in truth.motors.items():
        if motor.channel is None or motor.ticks_per_rad is None:
            continue
        got = found.motors[name]
        assert got.ticks_per_rad is not None
        ticks = max(ticks, abs(got.ticks_per_rad / motor.ticks_per_rad - 1))
        off = (got.zero_offset_ticks - motor.zero_offset_ticks + 2**31) % 2**32 - 2**31
        zero_deg = max(zero_deg, abs(math.degrees(off / motor.ticks_per_rad)))
    return axes, signs, scale, ticks, zero_deg


def run_seed(seed: int, telemetry_hz: float, field: bool, out_dir: Path) -> Row:
    """Calibrate one scrambled robot over UDP; compare with its hidden truth."""
    base_data: dict[str, Any] = load_profile_data()
    base = load_profile()
    truth = parse_profile(scramble_profile_data(base_data, seed))
    faults = FaultConfig(latency_ms=20.0, jitter_ms=10.0, loss=0.05) if field else None
    sim = RobotSimulator(
        truth,
        telemetry_hz=telemetry_hz,
        video_fps=0.0,
        faults=faults,
        noise_deg=0.2 if field else 0.0,
        seed=seed,
    )
    with sim:
        recorder = StateRecorder(sim)
        link = UdpLink(raw_profile(base), sim.address, extension=False)
        calibrator = Calibrator(link, base, AutoOperator(), deadman=OnStand(), stop=StopSignal())
        started = time.monotonic()
        try:
            result = calibrator.run()
        finally:
            link.shutdown()
        wall_s = time.monotonic() - started
        recorder.stop()
    start = recorder.samples[0].joints_rad
    excursion = max(
        math.degrees(max(abs(s.joints_rad[n] - start[n]) for s in recorder.samples)) for n in start
    )
    b_axes, _, b_scale, b_ticks, _ = _errors(base, truth)
    if result.aborted is not None:
        return Row(seed, False, False, math.nan, math.nan, math.nan, wall_s, excursion,
                   b_axes, b_scale, b_ticks, result.aborted)  # fmt: skip
    path = out_dir / f"calibrated-{seed}.toml"
    write_calibrated_profile(path, base_data, result, robot="bench", base_name="engineer.toml")
    axes, signs, scale, ticks, zero_deg = _errors(load_profile(path), truth)
    return Row(seed, axes, signs, scale, ticks, zero_deg, wall_s, excursion,
               b_axes, b_scale, b_ticks, None)  # fmt: skip


def main() -> None:
    """Run the seeds and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--telemetry-hz", type=float, default=20.0)
    parser.add_argument("--field", action="store_true", help="latency, loss and noise")
    args = parser.parse_args()
    conditions = (
        "20 ± 10 ms each way, 5 % loss each way, ±0.2° noise" if args.field else "perfect link"
    )
    print(f"ocu calibrate --yes vs ocu-sim --scramble SEED over UDP 127.0.0.1, "
          f"telemetry {args.telemetry_hz:g} Hz, {conditions}")  # fmt: skip
    header = (
        f"{'seed':>4} {'axes':>5} {'signs':>5} {'scale err':>9} {'ticks err':>9} "
        f"{'zero err':>8} {'time s':>7} {'max exc °':>9} | {'profile: axes':>13} "
        f"{'scale err':>9} {'ticks err':>9}"
    )
    print(header)
    rows: list[Row] = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            row = run_seed(seed, args.telemetry_hz, args.field, Path(tmp))
            rows.append(row)
            print(
                f"{row.seed:>4} {'exact' if row.axes_exact else 'WRONG':>5} "
                f"{'exact' if row.signs_exact else 'WRONG':>5} {row.scale_err * 100:>8.2f}% "
                f"{row.ticks_err * 100:>8.2f}% {row.zero_err_deg:>7.2f}° {row.duration_s:>7.1f} "
                f"{row.excursion_deg:>9.2f} | {'exact' if row.base_axes_exact else 'wrong':>13} "
                f"{row.base_scale_err * 100:>8.1f}% {row.base_ticks_err * 100:>8.1f}%"
                + (f"  ABORTED: {row.aborted}" if row.aborted else ""),
                flush=True,
            )
    ok = [r for r in rows if r.aborted is None]
    if ok:
        print(
            f"all seeds: axes and signs exact {sum(r.axes_exact and r.signs_exact for r in ok)}"
            f"/{len(rows)}; worst scale {max(r.scale_err for r in ok) * 100:.2f} %, worst ticks "
            f"{max(r.ticks_err for r in ok) * 100:.2f} % (target 2 %); time "
            f"{min(r.duration_s for r in ok):.1f}-{max(r.duration_s for r in ok):.1f} s; "
            f"largest excursion {max(r.excursion_deg for r in ok):.2f}° (target < 10°)"
        )


if __name__ == "__main__":
    main()
