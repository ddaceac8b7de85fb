"""Link benchmarks: command latency, e-stop under loss, idle CPU of the link thread.

    .venv/bin/python bench/bench_link.py                # all three
    .venv/bin/python bench/bench_link.py latency        # one of: latency, estop, cpu

Each prints its figure next to a baseline measured in the same run.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import os
import random
import sys
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from common import StampingRobot, percentile

from ocu.link.base import Link
from ocu.link.live import LinkOptions, UdpLink, VirtualLink
from ocu.net.transport import VirtualWire
from ocu.profile import RobotProfile, load_profile
from ocu.sim.faults import FaultConfig
from ocu.sim.simulator import RobotSimulator


def command_latency(
    profile: RobotProfile, count: int, send_on_change: bool, backend: str = "udp"
) -> list[float]:
    """Seconds from set_velocities() to the datagram's arrival, per change."""
    wire = VirtualWire() if backend == "virtual" else None
    robot = StampingRobot(profile, "waist", transport=wire.robot if wire else None)
    options: LinkOptions = {
        "gui_alive_timeout_s": None,
        "link_lost_after_s": 3600.0,
        "send_on_change": send_on_change,
    }
    link: Link
    if wire is not None:
        link = VirtualLink(profile, wire.ocu, **options)
    else:
        link = UdpLink(profile, robot.address, **options)
    link.start()
    per_unit = profile.channels["waist"].axis_per_unit
    rng = random.Random(7)
    latencies = []
    try:
        for i in range(1, count + 1):
            value = (i % 9000 + 1) / per_unit
            axis_value = round(value * per_unit)
            if not send_on_change:
                # Changes fall at random phases of the tick, as an operator's would.
                time.sleep(rng.uniform(0.0, 1.0 / link.rate_hz))
            changed = time.perf_counter()
            link.set_velocities(waist=value)
            latencies.append(robot.wait_for(axis_value, 2.0) - changed)
    finally:
        link.shutdown()
        robot.close()
        if wire is not None:
            wire.close()
    return latencies


def bench_latency(profile: RobotProfile) -> None:
    immediate = command_latency(profile, 1000, send_on_change=True)
    virtual = command_latency(profile, 1000, send_on_change=True, backend="virtual")
    tick_only = command_latency(profile, 100, send_on_change=False)
    p50, p99 = percentile(immediate, 50) * 1e3, percentile(immediate, 99) * 1e3
    tick_p50 = percentile(tick_only, 50) * 1e3
    print("command change -> datagram on 127.0.0.1")
    print(f"  send at once : p50 {p50:.3f} ms  p99 {p99:.3f} ms  (1000 changes)")
    print(
        f"  virtual wire : p50 {percentile(virtual, 50) * 1e3:.3f} ms  "
        f"p99 {percentile(virtual, 99) * 1e3:.3f} ms  (1000 changes, VirtualLink)"
    )
    print(
        f"  5 Hz tick only: p50 {tick_p50:.1f} ms  p99 "
        f"{percentile(tick_only, 99) * 1e3:.1f} ms  (100 changes)"
    )
    print(f"  tick-only median / at-once p99 = {tick_p50 / p99:.0f}x  (target p99 < 5 ms, >= 20x)")


def estop_times(profile: RobotProfile, trials: int, repeats: int, seed: int) -> list[float]:
    """Seconds from emergency_stop() until the simulator has every motor stopped."""
    link_settings = dataclasses.replace(profile.link, estop_repeats=repeats)
    bench_profile = dataclasses.replace(profile, link=link_settings)
    sim = RobotSimulator(
        bench_profile,
        telemetry_hz=5.0,
        video_fps=0.0,
        faults=FaultConfig(loss=0.3),
        seed=seed,
    )
    sim.start()
    link = UdpLink(bench_profile, sim.address, gui_alive_timeout_s=None, link_lost_after_s=3600.0)
    link.start()
    times = []
    try:
        for _ in range(trials):
            link.set_velocities(drive_linear=0.3)
            if not sim.wait_until(lambda s: not s.all_stopped, 5.0):
                raise RuntimeError("robot never started moving")
            started = time.monotonic()
            link.emergency_stop("bench")
            if not sim.wait_until(lambda s: s.all_stopped, 5.0):
                raise RuntimeError("robot never stopped")
            times.append(max(sim.state().time_s - started, 0.0))
    finally:
        link.shutdown()
        sim.stop()
    return times


def bench_estop(profile: RobotProfile) -> None:
    burst = estop_times(profile, 200, profile.link.estop_repeats, seed=1)
    single = estop_times(profile, 200, 1, seed=1)
    print("e-stop -> simulator reports all motors stopped, 30% loss each way, 200 trials")
    for name, times in (("burst of 5  ", burst), ("single zero ", single)):
        print(
            f"  {name}: p50 {percentile(times, 50) * 1e3:.1f} ms  "
            f"p99 {percentile(times, 99) * 1e3:.1f} ms  max {max(times) * 1e3:.1f} ms"
        )
    print("  (target: burst p99 < 250 ms; the single packet waits for the 5 Hz tick when lost)")


def thread_cpu_s(native_id: int) -> float:
    """CPU seconds (user + system) used so far by one thread of this process."""
    with open(f"/proc/self/task/{native_id}/stat", encoding="ascii") as stat:
        fields = stat.read().rsplit(")", 1)[1].split()
    ticks = os.sysconf("SC_CLK_TCK")
    return (int(fields[11]) + int(fields[12])) / ticks


def bench_cpu(profile: RobotProfile, seconds: float = 20.0) -> None:
    sim = RobotSimulator(profile, video_fps=0.0)
    sim.start()
    link = UdpLink(profile, sim.address, gui_alive_timeout_s=None)
    link.start()
    try:
        thread = next(t for t in threading.enumerate() if t.name == "ocu-link")
        assert thread.native_id is not None
        tid = thread.native_id
        before = thread_cpu_s(tid)
        done = threading.Event()
        done.wait(seconds)
        used = thread_cpu_s(tid) - before
    finally:
        link.shutdown()
        sim.stop()
    sent = link.stats().sent
    print(f"link thread idle at 5 Hz with 1 Hz telemetry for {seconds:.0f} s:")
    print(f"  CPU {100 * used / seconds:.2f}% of one core ({sent} RCPs sent)  (target < 1%)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("which", nargs="*", default=["latency", "estop", "cpu"])
    args = parser.parse_args()
    logging.basicConfig(level=logging.ERROR)  # the link logs every e-stop as a warning
    profile = load_profile()
    print(f"{os.cpu_count()} cores")
    for name in args.which:
        {"latency": bench_latency, "estop": bench_estop, "cpu": bench_cpu}[name](profile)


if __name__ == "__main__":
    main()
