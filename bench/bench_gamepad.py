"""Stick change to datagram on the wire, through the whole console: p50/p99 over 500 changes.

SDL's virtual pad moves the left stick (drive; deadman held) between stop and three speeds;
the change goes through SDL, the "ocu-gamepad" poll thread (its wait included: changes land
at random moments), the Qt mailbox to the GUI thread, the teleop, the console model and the
link, onto a UDP socket; the simulator stamps the RCP when it reads it. Baseline from the
same run: a W key press through the keyboard path (bench_keys.py's measure, which delivers
the key synchronously). Then the right stick moving the arm: the 3D view redraws the moving
arm in software (OSMesa, offscreen) and a pad state waits behind each frame on the GUI
thread. Then the poll thread alone (no console): stick change -> state read, woken by SDL's
events (the console's way) against polling on a timer at 200 Hz and at 25 Hz
(QGroundControl's joystick rate). Also the poll thread's CPU, idle and with the stick moving.

    .venv/bin/python bench/bench_gamepad.py [--changes 500] [--baseline-changes 200]
"""

from __future__ import annotations

import argparse
import os
import random
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

from PySide6.QtCore import QEventLoop, QSettings, QTimer
from PySide6.QtWidgets import QApplication

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from bench_keys import measure as measure_keys
from common import percentile

from ocu.gamepad.mapping import load_pad_mapping, parse_pad_mapping
from ocu.gamepad.poller import THREAD_NAME, PadPoller
from ocu.gamepad.virtual import VirtualPad
from ocu.link.live import UdpLink
from ocu.profile import RobotProfile, load_profile
from ocu.records import LinkState
from ocu.sim.simulator import RobotSimulator
from ocu.windows.main_window import MainWindow

WAIT_S = 2.0
# Stick positions that each give a different command: for the drive, stop and three speeds
# above the servos' 0.2 m/s starting speed (slower ones are lifted to it); for the arm, five
# speeds (the teleop keeps a command until it moves by 1 % of the travel).
STICKS = {
    "drive": ("lefty", "drive_linear", (0, -26214, -29491, -32768)),
    "arm": ("righty", "shoulder", (-32768, -26000, -19000, -12000, -6000)),
}
CPU_S = 5.0
CHECK_MS = 2


def pump_until(done: Callable[[], bool], timeout_s: float) -> bool:
    """Run Qt's event loop until `done()` or the deadline.

    The GUI thread sleeps in the loop between events, as in the console: a thread spinning
    in Python here would hold the GIL and delay the poll thread by Python's switch interval.
    The latency measured does not depend on how soon this notices: the simulator stamps.
    """
    deadline = time.monotonic() + timeout_s
    loop = QEventLoop()

    def check() -> None:
        if done() or time.monotonic() >= deadline:
            loop.quit()

    timer = QTimer()
    timer.setInterval(CHECK_MS)
    timer.timeout.connect(check)
    timer.start()
    if not done():
        loop.exec()
    timer.stop()
    return done()


def pause(seconds: float) -> None:
    """Let Qt's event loop run for a while."""
    loop = QEventLoop()
    QTimer.singleShot(max(1, round(seconds * 1000)), loop.quit)
    loop.exec()


def thread_cpu_s(name: str) -> float:
    """User + system CPU seconds of one thread of this process, by name (Linux /proc)."""
    thread = next(t for t in threading.enumerate() if t.name == name)
    stat = Path(f"/proc/self/task/{thread.native_id}/stat").read_text().rsplit(")", 1)[1]
    fields = stat.split()
    ticks = int(fields[11]) + int(fields[12])  # utime, stime
    return ticks / os.sysconf("SC_CLK_TCK")


def measure_poller(changes: int, poll_hz: float, wake_on_events: bool) -> list[float]:
    """Stick change -> state stored by the poll thread (ms), no console."""
    changed = threading.Event()
    stored_at = [0.0]

    def on_state() -> None:
        stored_at[0] = time.monotonic()
        changed.set()

    poller = PadPoller(poll_hz, on_state, lambda _event: None, wake_on_events=wake_on_events)
    latencies = []
    rng = random.Random(2)
    with VirtualPad() as pad:
        poller.start()
        try:
            if not changed.wait(WAIT_S):
                raise RuntimeError("the poller did not open the pad")
            for index in range(changes):
                time.sleep(rng.uniform(0.005, 0.03))
                poller.take()
                changed.clear()
                changed_at = time.monotonic()
                pad.set_axis("righty", -20000 if index % 2 else 20000)
                if not changed.wait(WAIT_S):
                    raise RuntimeError("the poller did not see a stick change")
                latencies.append((stored_at[0] - changed_at) * 1000.0)
        finally:
            poller.stop()
    return latencies


def poller_cpu(poll_hz: float, seconds: float, pad_state: str) -> float:
    """The poll thread's CPU share (no console): with no pad, a pad at rest, or the stick
    sweeping without pause."""
    poller = PadPoller(poll_hz, lambda: None, lambda _event: None)
    with VirtualPad() as pad:
        if pad_state == "none":
            pad.detach()
        poller.start()
        try:
            time.sleep(0.3)
            before = thread_cpu_s(THREAD_NAME)
            start = time.monotonic()
            step = 0
            while time.monotonic() - start < seconds:
                if pad_state == "sweep":
                    step += 1
                    pad.set_axis("righty", (step * 997) % 60000 - 30000)
                    time.sleep(0.0005)
                else:
                    time.sleep(0.1)
            return (thread_cpu_s(THREAD_NAME) - before) / (time.monotonic() - start)
        finally:
            poller.stop()


def measure(
    app: QApplication, profile: RobotProfile, changes: int, poll_hz: float, stick: str = "drive"
) -> list[float]:
    """Stick-change-to-wire latencies (ms) through a console against the simulator."""
    mapping = parse_pad_mapping(
        {"options": {"poll_hz": poll_hz, "stall_timeout_ms": max(100.0, 4000.0 / poll_hz)}},
        profile,
        load_pad_mapping(profile),
        source="bench",
    )
    pad_axis, channel, levels = STICKS[stick]
    axis = profile.channels[channel].axis
    with (
        tempfile.TemporaryDirectory() as config,
        RobotSimulator(profile, telemetry_hz=10.0, video_fps=0.0) as sim,
        VirtualPad() as pad,
    ):
        settings = QSettings(os.path.join(config, "ocu.ini"), QSettings.Format.IniFormat)
        window = MainWindow(
            profile,
            lambda: UdpLink(profile, sim.address),
            "simulator",
            settings,
            pad_mapping=mapping,
        )
        window.show()
        window.activateWindow()
        if not pump_until(
            lambda: (
                window.link_status.state == LinkState.CONNECTED and window.teleop.info is not None
            ),
            10.0,
        ):
            raise RuntimeError("the console did not connect or did not see the pad")
        pad.set_button("leftshoulder", True)
        if not pump_until(lambda: window.teleop.engaged, WAIT_S):
            raise RuntimeError("the deadman did not engage the pad")
        rng = random.Random(1)
        latencies: list[float] = []
        level = 0
        last_axis = 0
        for _ in range(changes):
            # Random gaps: the changes land at random phases of the poll period.
            pause(rng.uniform(0.005, 0.03))
            level = rng.choice([i for i in range(len(levels)) if i != level])
            changed_at = time.monotonic()
            pad.set_axis(pad_axis, levels[level])

            def arrived(since: float = changed_at, old: int = last_axis) -> bool:
                return any(
                    r.time_s >= since and r.packet.axes[axis] != old
                    for r in sim.received_commands()[-50:]
                )

            if not pump_until(arrived, WAIT_S):
                raise RuntimeError("no RCP arrived for a stick change")
            rcp = next(
                r
                for r in sim.received_commands()[-50:]
                if r.time_s >= changed_at and r.packet.axes[axis] != last_axis
            )
            last_axis = rcp.packet.axes[axis]
            latencies.append((rcp.time_s - changed_at) * 1000.0)
        pad.set_button("leftshoulder", False)
        window.close()
        app.processEvents()
        return latencies


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--changes", type=int, default=500)
    parser.add_argument("--baseline-changes", type=int, default=200)
    parser.add_argument("--poll-hz", type=float, default=None, help="default: the mapping's")
    args = parser.parse_args()
    app = QApplication.instance() or QApplication([])
    assert isinstance(app, QApplication)
    profile = load_profile()
    poll_hz = args.poll_hz or load_pad_mapping(profile).poll_hz
    print(f"{os.cpu_count()} cores, Qt platform {app.platformName()}")
    ours = measure(app, profile, args.changes, poll_hz)
    keys = measure_keys(app, profile, args.baseline_changes, at_once=True, max_gap_s=0.02)
    arm = measure(app, profile, args.baseline_changes, poll_hz, stick="arm")
    woken = measure_poller(args.baseline_changes, poll_hz, wake_on_events=True)
    timer = measure_poller(args.baseline_changes, poll_hz, wake_on_events=False)
    slow = measure_poller(args.baseline_changes, 25.0, wake_on_events=False)
    cpu = {state: poller_cpu(poll_hz, CPU_S, state) for state in ("none", "idle", "sweep")}

    def row(values: list[float]) -> str:
        return (
            f"p50 {percentile(values, 50):.2f} ms  p99 {percentile(values, 99):.2f} ms  "
            f"max {max(values):.2f} ms  ({len(values)})"
        )

    print("left stick change (drive; virtual pad, deadman held) -> RCP read by the simulator")
    print(f"  the console       : {row(ours)}  (target p99 < 15 ms)")
    print(f"  W key press, same : {row(keys)}  (delivered synchronously by QTest)")
    print(f"right stick moving the arm (the 3D view redraws in software): {row(arm)}")
    print("stick change -> state read by the poll thread alone (no console)")
    print(f"  woken by SDL's events ({poll_hz:.0f} Hz heartbeat): {row(woken)}")
    print(f"  polled on a timer at {poll_hz:.0f} Hz      : {row(timer)}")
    print(f"  polled at 25 Hz (QGroundControl)  : {row(slow)}")
    print(f"  25 Hz p99 / woken p99 = {percentile(slow, 99) / percentile(woken, 99):.1f}x")
    print(
        f"poll thread CPU, % of one core: no pad {100 * cpu['none']:.2f}, pad at rest "
        f"{100 * cpu['idle']:.2f}, stick sweeping {100 * cpu['sweep']:.2f}"
    )


if __name__ == "__main__":
    main()
