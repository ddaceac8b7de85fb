"""The UR link against the UR simulator over TCP on 127.0.0.1, at 0 and 50 ms one-way latency.

- **command -> arm moving** (speedj streamed): from `set_command` to the simulator's arm
  moving (its snapshot polled every 0.5 ms), and to the OCU seeing it move (the first
  telemetry frame with the joint's actual speed non-zero: one more trip back). Wrist 3 at
  0.5 rad/s from rest, 20 trials.
- **SIGKILL -> at rest**: an OCU process (a UrLink driving wrist 3 at 0.5 rad/s) killed with
  SIGKILL; the time until the simulator's arm is at rest (wall, polled), and in controller
  time from the last command the controller took to rest. 5 trials.
- **reconnection**: the controller drops every connection; the time until the link is
  CONNECTED again (its first realtime packet on the new connection). 10 trials.

    nice -n 5 .venv/bin/python bench/bench_ur.py            # ~1 min on 2 cores
"""

from __future__ import annotations

import argparse
import logging
import os
import signal
import statistics
import subprocess
import sys
import threading
import time
from collections.abc import Callable

from ocu.link.ur import UrLink
from ocu.profile.ur import load_ur_profile
from ocu.records import Command, LinkEvent, LinkState, LinkStateChanged, TelemetryFrame
from ocu.sim.ur import UrSimulator

WRIST_3 = "wrist_3_joint"
SPEED = 0.5
DEADLINE_S = 10.0


def wait_for(condition: Callable[[], bool], what: str, poll_s: float = 0.0005) -> float:
    """Wait for `condition`; the monotonic time it was first seen true."""
    deadline = time.monotonic() + DEADLINE_S
    while not condition():
        if time.monotonic() > deadline:
            raise RuntimeError(f"not {what} within {DEADLINE_S} s")
        time.sleep(poll_s)
    return time.monotonic()


def at_rest(sim: UrSimulator) -> bool:
    return all(abs(v) < 1e-9 for v in sim.snapshot().qd)


def summary(values: list[float]) -> str:
    ms = sorted(v * 1000 for v in values)
    p95 = ms[min(len(ms) - 1, round(0.95 * (len(ms) - 1)))]
    return (
        f"median {statistics.median(ms):6.1f} ms, p95 {p95:6.1f}, max {ms[-1]:6.1f} (n={len(ms)})"
    )


class Watcher:
    """When the link first saw wrist 3 move, and its state changes."""

    def __init__(self) -> None:
        self.moving_at: float | None = None
        self.connected_at: float | None = None
        self.speed = 0.0
        self.lock = threading.Lock()

    def __call__(self, event: LinkEvent) -> None:
        now = time.monotonic()
        with self.lock:
            if isinstance(event, TelemetryFrame):
                reading = event.readings[WRIST_3]
                self.speed = reading.speed_rad_s
                if self.moving_at is None and abs(reading.speed_rad_s) > 1e-9:
                    self.moving_at = now
            elif isinstance(event, LinkStateChanged) and event.state is LinkState.CONNECTED:
                self.connected_at = now

    def reset(self) -> None:
        with self.lock:
            self.moving_at = None
            self.connected_at = None


def ports_of(sim: UrSimulator) -> tuple[int, int, int]:
    return (sim.ports["primary"], sim.ports["secondary"], sim.ports["realtime"])


def bench_latency(latency_ms: float, trials: int) -> None:
    arm = load_ur_profile("ur5e")
    with UrSimulator(arm, ports=(0, 0, 0), latency_ms=latency_ms) as sim:
        watcher = Watcher()
        link = UrLink(
            arm, sim.host, ports=ports_of(sim), listener=watcher, gui_alive_timeout_s=None
        )
        link.start()
        try:
            wait_for(lambda: link.state is LinkState.CONNECTED, "connected")
            at_arm: list[float] = []
            seen: list[float] = []
            for trial in range(trials):
                link.set_command(Command())
                wait_for(lambda: at_rest(sim), "at rest")
                # What is still in flight from the last trial must have arrived.
                wait_for(lambda: abs(watcher.speed) < 1e-9, "the OCU seeing it at rest")
                # A new command each time (the speed differs a little): never the held one.
                speed = SPEED + 0.001 * trial
                watcher.reset()
                started = time.monotonic()
                link.set_command(Command({WRIST_3: speed}))
                moving = wait_for(lambda: abs(sim.snapshot().qd[5]) > 1e-9, "the arm moving")
                at_arm.append(moving - started)
                wait_for(lambda: watcher.moving_at is not None, "the OCU seeing it")
                assert watcher.moving_at is not None
                seen.append(watcher.moving_at - started)
            print(f"  command -> arm moving:        {summary(at_arm)}")
            print(f"  command -> OCU sees it move:  {summary(seen)}")

            reconnect: list[float] = []
            for _ in range(trials // 2):
                watcher.reset()
                dropped = time.monotonic()
                sim.drop_connections()
                wait_for(lambda: watcher.connected_at is not None, "reconnected", 0.001)
                assert watcher.connected_at is not None
                reconnect.append(watcher.connected_at - dropped)
            print(f"  drop -> CONNECTED again:      {summary(reconnect)}")
        finally:
            link.shutdown()


def bench_sigkill(latency_ms: float, trials: int) -> None:
    arm = load_ur_profile("ur5e")
    wall: list[float] = []
    controller: list[float] = []
    for _ in range(trials):
        with UrSimulator(arm, ports=(0, 0, 0), latency_ms=latency_ms) as sim:
            args = [sys.executable, os.path.abspath(__file__), "--child", sim.host]
            args += [str(p) for p in ports_of(sim)]
            child = subprocess.Popen(args, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
            try:
                assert child.stdout is not None
                if child.stdout.readline().strip() != "moving":
                    raise RuntimeError("the child did not start driving")
                wait_for(lambda: abs(sim.snapshot().qd[5] - SPEED) < 1e-6, "the child driving")
                child.send_signal(signal.SIGKILL)
                killed = time.monotonic()
                rest = wait_for(lambda: at_rest(sim), "at rest")
                snapshot = sim.snapshot()
                wall.append(rest - killed)
                controller.append(snapshot.time_s - snapshot.last_command_s)
            finally:
                child.kill()
                child.wait()
                for stream in (child.stdin, child.stdout):
                    if stream is not None:
                        stream.close()
    print(f"  SIGKILL -> at rest (wall):    {summary(wall)}")
    print(f"  last command -> rest (ctrl):  {summary(controller)}  (<=, polled)")


def child(host: str, ports: list[str]) -> None:
    """The OCU process the SIGKILL bench kills: drives wrist 3 and heartbeats."""
    arm = load_ur_profile("ur5e")
    link = UrLink(arm, host, ports=(int(ports[0]), int(ports[1]), int(ports[2])))
    link.start()
    wait_for(lambda: link.state is LinkState.CONNECTED, "connected")
    link.heartbeat()
    link.set_command(Command({WRIST_3: SPEED}))
    print("moving", flush=True)
    while True:
        link.heartbeat()
        time.sleep(0.05)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=20)
    parser.add_argument("--child", nargs=4, metavar=("HOST", "P1", "P2", "P3"))
    args = parser.parse_args()
    logging.basicConfig(level=logging.ERROR)
    if args.child:
        child(args.child[0], args.child[1:])
        return
    for latency_ms in (0.0, 50.0):
        print(f"UR5e simulator (5.10, 500 Hz), speedj at 125 Hz, {latency_ms:g} ms one-way latency")
        bench_latency(latency_ms, args.trials)
        bench_sigkill(latency_ms, max(1, args.trials // 4))


if __name__ == "__main__":
    main()
