"""bench_live.py's console figures: the console's CPU serving four cameras (`--console N`) and
the operator's key -> datagram with 20 clients attached (`--keys N`); see bench_live.py."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import percentile

from ocu.profile import RobotProfile
from ocu.record import schemas as s
from tests.live.node_client import NodeClient, count

ROOT = Path(__file__).resolve().parents[1]
SERVING = re.compile(r"live: serving on ws://127\.0\.0\.1:(\d+)")
SETTLE_S = 10.0  # the console starts its simulator, connects and fills its views
TICK_HZ = os.sysconf("SC_CLK_TCK")


def process_cpu_s(pid: int) -> float:
    """User + system CPU seconds of one process (not its children: the simulator is one)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICK_HZ


def start_console(config: str, *options: str) -> subprocess.Popen[str]:
    env = {**os.environ, "QT_QPA_PLATFORM": "offscreen", "PYTHONPATH": str(ROOT)}
    env.pop("OCU_LIVE_TOKEN", None)
    command = [sys.executable, "-m", "ocu", "--config-dir", config, "--no-gamepad"]
    return subprocess.Popen(
        [*command, "--sim-arg=--extended", *options],
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )


def served_port(process: subprocess.Popen[str]) -> int:
    assert process.stderr is not None
    for line in process.stderr:
        found = SERVING.search(line)
        if found:
            return int(found.group(1))
    raise RuntimeError("the console ended before serving")


def relay_pids(pid: int) -> list[int]:
    """The console's live relay process (ocu.live.relay), if it runs one."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            parent = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            command = (entry / "cmdline").read_bytes()
        except (OSError, IndexError, ValueError):
            continue
        if parent == pid and b"ocu.live.relay" in command:
            found.append(int(entry.name))
    return found


def cpu_percent(pid: int, phase_s: float, relay_share: list[float] | None = None) -> float:
    """The console's CPU with its live relay's (the serving it does for the console); the
    relay's alone appended to `relay_share`."""
    relays = relay_pids(pid)
    start = process_cpu_s(pid), sum(process_cpu_s(p) for p in relays)
    time.sleep(phase_s)  # the measurement's phase, not synchronisation
    own = (process_cpu_s(pid) - start[0]) / phase_s * 100.0
    relay = (sum(process_cpu_s(p) for p in relays) - start[1]) / phase_s * 100.0
    if relay_share is not None:
        relay_share.append(relay)
    return own + relay


def stop(process: subprocess.Popen[str]) -> None:
    process.send_signal(signal.SIGTERM)
    try:
        process.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        process.kill()
        process.communicate()


def console_cpu(profile: RobotProfile, clients_n: int, phase_s: float, rounds: int = 3) -> None:
    """The console's CPU (with its live relay's): --live off, --live with no client, --live
    with N camera clients; `rounds` times in turn, as the machine's other load comes and
    goes."""
    cameras = [s.camera_topic(name) for name in profile.link.camera_names]
    topics = [s.JOINT_STATES, "/tf", *cameras]
    results: dict[str, list[float]] = {"off": [], "idle": [], "clients": []}
    relay: dict[str, list[float]] = {"off": [], "idle": [], "clients": []}
    rates: list[float] = []
    with tempfile.TemporaryDirectory() as config:
        for _ in range(rounds):
            off = start_console(config)
            try:
                time.sleep(SETTLE_S)
                results["off"].append(cpu_percent(off.pid, phase_s))
            finally:
                stop(off)
            on = start_console(config, "--live", "127.0.0.1:0")
            assert on.stderr is not None
            try:
                port = served_port(on)
            except BaseException:
                stop(on)
                raise
            # The rest of its log is not read: it must not fill the pipe.
            drain = subprocess.Popen(["cat"], stdin=on.stderr, stdout=subprocess.DEVNULL)
            try:
                time.sleep(SETTLE_S)
                results["idle"].append(cpu_percent(on.pid, phase_s, relay["idle"]))
                url = f"ws://127.0.0.1:{port}"
                clients = [NodeClient(url, topics=topics, brief=True) for _ in range(clients_n)]
                try:
                    for client in clients:
                        assert client.wait(count(s.JOINT_STATES, 10), 60.0)
                    marks = [len(c.events) for c in clients]
                    results["clients"].append(cpu_percent(on.pid, phase_s, relay["clients"]))
                    frames = sum(
                        1
                        for client, mark in zip(clients, marks, strict=True)
                        for event in client.events[mark:]
                        if event.get("topic") in cameras
                    )
                    rates.append(frames / phase_s / clients_n)
                finally:
                    for client in clients:
                        client.close()
            finally:
                stop(on)
                drain.wait(10)
            print(
                f"round: off {results['off'][-1]:.1f} %, --live no client "
                f"{results['idle'][-1]:.1f} %, {clients_n} clients {results['clients'][-1]:.1f} %"
            )
    off_mean = sum(results["off"]) / rounds
    for label, key in (
        ("--live off", "off"),
        ("--live, no client", "idle"),
        (f"--live, {clients_n} clients", "clients"),
    ):
        mean = sum(results[key]) / rounds
        share = f", of which the relay {sum(relay[key]) / rounds:.1f} %" if relay[key] else ""
        print(
            f"console, {label:18s}: CPU {mean:5.1f} % of a core (mean of {rounds}, "
            f"{min(results[key]):.1f}-{max(results[key]):.1f}; {mean - off_mean:+.1f} against "
            f"off{share})"
        )
    print(f"camera frames/s per client: {sum(rates) / len(rates):.1f} ({len(cameras)} cameras)")


def keys(profile: RobotProfile, presses: int, clients_n: int = 20) -> None:
    """bench_keys's W presses: no server, a server and no client, a server and 20 clients."""
    from bench_core import WireProbe
    from bench_keys import WAIT_S, first_rcp_after, pump
    from PySide6.QtCore import QSettings, Qt
    from PySide6.QtTest import QTest
    from PySide6.QtWidgets import QApplication

    from ocu.link.live import UdpLink
    from ocu.live.options import serving
    from ocu.live.server import LiveServer
    from ocu.records import LinkState
    from ocu.sim.simulator import RobotSimulator
    from ocu.windows.main_window import MainWindow

    app = QApplication.instance() or QApplication([])
    assert isinstance(app, QApplication)
    # The clients run on this machine's cores; niced to 19 they stand in for clients on other
    # machines (what the server costs, without the clients' own decoding in the way).
    for label, served, n, nice in (
        ("no live server", False, 0, 0),
        ("live, no client", True, 0, 0),
        (f"live, {clients_n} clients", True, clients_n, 0),
        (f"live, {clients_n} niced", True, clients_n, 19),
    ):
        with (
            tempfile.TemporaryDirectory() as config,
            RobotSimulator(profile, telemetry_hz=50.0, video_fps=0.0) as sim,
        ):
            server = LiveServer(profile, "127.0.0.1", 0) if served else None
            if server is not None:
                server.start()
            settings = QSettings(os.path.join(config, "ocu.ini"), QSettings.Format.IniFormat)

            probe = WireProbe(profile)

            def make_link(
                address: tuple[str, int] = sim.address, probe: WireProbe = probe
            ) -> UdpLink:
                link = UdpLink(profile, address, send_on_change=True)
                link.subscribe(probe.on_event)
                return link

            window = MainWindow(profile, serving(server, make_link), "simulator", settings)
            window.show()
            window.activateWindow()
            deadline = time.monotonic() + 10.0
            while window.link_status.state != LinkState.CONNECTED and time.monotonic() < deadline:
                pump(app, 0.05)
            clients = []
            if server is not None:
                url = f"ws://127.0.0.1:{server.address[1]}"
                # quiet: the clients' events are not read here per message (their reader
                # threads would share this process's GIL with the window).
                clients = [NodeClient(url, topics=["*"], brief=True, quiet=True) for _ in range(n)]
                for client in clients:
                    if nice:
                        os.setpriority(os.PRIO_PROCESS, client.process.pid, nice)
            try:
                for client in clients:
                    while not client.wait(count(s.JOINT_STATES, 10), 0.05):
                        pump(app, 0.05)
                latencies: list[float] = []
                wire: list[float] = []
                missed = 0
                for k in range(presses):
                    pump(app, 0.005 + 0.015 * ((k * 7919) % 100) / 100.0)
                    sent = len(sim.received_commands())
                    pressed_at = probe.arm("moving")
                    QTest.keyPress(window, Qt.Key.Key_W)
                    try:
                        rcp = first_rcp_after(sim, profile, sent, moving=True)
                        latencies.append((rcp.time_s - pressed_at) * 1000.0)
                        with probe.lock:
                            if probe.found is not None:
                                wire.append((probe.found - pressed_at) * 1000.0)
                    except RuntimeError:  # the console stopped motion: a stalled cycle
                        missed += 1
                    sent = len(sim.received_commands())
                    QTest.keyRelease(window, Qt.Key.Key_W)
                    try:
                        first_rcp_after(sim, profile, sent, moving=False)
                    except RuntimeError:
                        pump(app, 0.5)
            finally:
                for client in clients:
                    client.close()
                got = [
                    max((e["counts"].get(s.JOINT_STATES, 0) for e in c.of("counts")), default=0)
                    for c in clients
                ]
                window.close()
                app.processEvents()
                if server is not None:
                    server.stop()
        seen = f", each client got >= {min(got)} /joint_states" if got else ""
        print(
            f"W key -> datagram sent, {label:17s}: p50 {percentile(wire, 50):.2f} ms  "
            f"p99 {percentile(wire, 99):.2f} ms  max {max(wire):.2f} ms ({len(wire)} presses)"
        )
        print(
            f"W key -> RCP, {label:17s}: p50 {percentile(latencies, 50):.2f} ms  "
            f"p99 {percentile(latencies, 99):.2f} ms  max {max(latencies):.2f} ms "
            f"({len(latencies)} presses, {missed} without motion in {WAIT_S:g} s{seen})"
        )
