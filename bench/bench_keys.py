"""Key press to datagram on the wire, through the whole console: p50/p99 over 500 presses.

A W key press goes through Qt's event delivery, the console's application event filter,
ocu.hotkeys, the operator model and the link, onto a UDP socket; the simulator stamps the
RCP when it reads it. Baseline from the same run: a link that sends only on its periodic
5 Hz tick, as the paper's client does. Then the same presses (and their releases) while the
robot floods the link with telemetry (`--flood-hz`, 1000 packets/s): the views take telemetry
at most 30 times a second, so the flood must not delay the keys.

    .venv/bin/python bench/bench_keys.py [--presses 500] [--baseline-presses 60]
"""

from __future__ import annotations

import argparse
import os
import random
import sys
import tempfile
import time

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

from PySide6.QtCore import QSettings, Qt
from PySide6.QtTest import QTest
from PySide6.QtWidgets import QApplication

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from common import percentile

from ocu.link.live import UdpLink
from ocu.profile import RobotProfile, load_profile
from ocu.records import LinkState
from ocu.sim.simulator import ReceivedRcp, RobotSimulator
from ocu.windows.main_window import MainWindow

WAIT_S = 2.0


def pump(app: QApplication, seconds: float) -> None:
    """Run the event loop for a while (heartbeats, telemetry)."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        app.processEvents()
        time.sleep(0.001)


def first_rcp_after(
    sim: RobotSimulator, profile: RobotProfile, count: int, moving: bool
) -> ReceivedRcp:
    """Wait for the first RCP after `count` whose drive axis is (non)zero."""
    axis = profile.channels["drive_linear"].axis

    def arrived(_state: object) -> bool:
        return any((r.packet.axes[axis] != 0) == moving for r in sim.received_commands()[count:])

    if not sim.wait_until(arrived, WAIT_S):
        raise RuntimeError("no RCP arrived for a key event")
    return next(r for r in sim.received_commands()[count:] if (r.packet.axes[axis] != 0) == moving)


def measure(
    app: QApplication,
    profile: RobotProfile,
    presses: int,
    at_once: bool,
    max_gap_s: float,
    *,
    telemetry_hz: float = 10.0,
    releases: list[float] | None = None,
) -> list[float]:
    """Press-to-wire latencies (ms) of W presses on a console against the simulator.

    With `releases`, the release-to-zero latencies are appended to it.
    """
    with (
        tempfile.TemporaryDirectory() as config,
        RobotSimulator(profile, telemetry_hz=telemetry_hz, video_fps=0.0) as sim,
    ):
        settings = QSettings(os.path.join(config, "ocu.ini"), QSettings.Format.IniFormat)

        def make_link() -> UdpLink:
            return UdpLink(profile, sim.address, send_on_change=at_once)

        window = MainWindow(profile, make_link, "simulator", settings)
        window.show()
        window.activateWindow()
        deadline = time.monotonic() + 10.0
        while window.link_status.state != LinkState.CONNECTED and time.monotonic() < deadline:
            pump(app, 0.05)
        latencies: list[float] = []
        rng = random.Random(1)
        for _ in range(presses):
            pump(app, rng.uniform(0.005, max_gap_s))
            count = len(sim.received_commands())
            pressed_at = time.monotonic()
            QTest.keyPress(window, Qt.Key.Key_W)
            rcp = first_rcp_after(sim, profile, count, moving=True)
            latencies.append((rcp.time_s - pressed_at) * 1000.0)
            count = len(sim.received_commands())
            released_at = time.monotonic()
            QTest.keyRelease(window, Qt.Key.Key_W)
            stop = first_rcp_after(sim, profile, count, moving=False)
            if releases is not None:
                releases.append((stop.time_s - released_at) * 1000.0)
        window.close()
        app.processEvents()
        return latencies


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--presses", type=int, default=500)
    parser.add_argument("--baseline-presses", type=int, default=60)
    parser.add_argument("--flood-hz", type=float, default=1000.0, help="0: no flood run")
    args = parser.parse_args()
    app = QApplication.instance() or QApplication([])
    assert isinstance(app, QApplication)
    profile = load_profile()
    print(f"{os.cpu_count()} cores, Qt platform {app.platformName()}")
    ours = measure(app, profile, args.presses, at_once=True, max_gap_s=0.02)
    # Gaps over a whole tick period, so presses land at random phases of the tick.
    tick_s = 1.0 / profile.link.send_rate_hz
    base = measure(app, profile, args.baseline_presses, at_once=False, max_gap_s=tick_s)
    print("W key press -> RCP read by the simulator on 127.0.0.1")
    print(
        f"  console      : p50 {percentile(ours, 50):.2f} ms  p99 {percentile(ours, 99):.2f} ms"
        f"  max {max(ours):.2f} ms  ({len(ours)} presses)  (target p99 < 10 ms)"
    )
    print(
        f"  tick-only 5 Hz: p50 {percentile(base, 50):.1f} ms  p99 {percentile(base, 99):.1f} ms"
        f"  ({len(base)} presses, the paper's client)"
    )
    print(f"  tick-only median / console p99 = {percentile(base, 50) / percentile(ours, 99):.0f}x")
    if args.flood_hz > 0:
        releases: list[float] = []
        flood = measure(
            app, profile, args.presses, True, 0.02, telemetry_hz=args.flood_hz, releases=releases
        )
        print(f"the same under a telemetry flood of {args.flood_hz:.0f} packets/s")
        print(
            f"  press -> RCP  : p50 {percentile(flood, 50):.2f} ms  "
            f"p99 {percentile(flood, 99):.2f} ms  max {max(flood):.2f} ms  (target p99 < 10 ms)"
        )
        print(
            f"  release -> zero: p50 {percentile(releases, 50):.2f} ms  "
            f"p99 {percentile(releases, 99):.2f} ms  max {max(releases):.2f} ms"
        )


if __name__ == "__main__":
    main()
