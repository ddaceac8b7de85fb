"""Live serving: telemetry packet -> message at a subscribed client, and the CPU it costs.

    .venv/bin/python bench/bench_live.py                      # 1, 5, 20 clients, 10 s each
    .venv/bin/python bench/bench_live.py --clients 1 5 --phase-s 20

The simulator runs in its own process (`ocu-sim --extended`: four cameras through the
protocol extension, telemetry at 50 Hz); this process holds a UdpLink and the
LiveServer, as the console does. Each client is the npm FoxgloveClient (tests/live/js, run by
Node.js) subscribed to /joint_states, /tf and every camera; it stamps each message's arrival
with its wall clock. Latency: that arrival less the message's receive time (the wall clock
when the link got the telemetry datagram), p50/p99 over the phase. CPU: this process (link,
the server's console side, no GUI) with the server's relay process, per phase, in % of one
core, with a phase of no clients first as the baseline.

    .venv/bin/python bench/bench_live.py --teleop 20      # client Twist -> datagram

--teleop N: the control core (HeadlessConsole) on an in-process simulator over UDP, the
server with --live-control; one npm client publishes a Twist once a second (a Teleop panel's
default: the robot stops between messages), N; latency from its send to the simulator's
first datagram carrying the drive, p50/p99.

    .venv/bin/python bench/bench_live.py --stream 600     # client Twist stream -> datagram

--stream N: the same path, one client publishing N Twists at 10 Hz whose linear.x
alternates between two speeds; latency from each send to the simulator's first datagram
carrying that speed, p50/p99 (the robot in motion, as a panel at a usable rate drives it).

    .venv/bin/python bench/bench_live.py --console 5      # the console's CPU, cameras

--console N: the real console (`ocu --sim-arg=--extended`: its built-in simulator in its own
process, four cameras), first without --live, then with --live and no client, then with N
npm clients subscribed to the four cameras, /joint_states and /tf; the console process's CPU
with its live relay's (ocu.live.relay; not the simulator's) per phase from /proc, in % of one
core; three rounds of the three, each console started afresh, as the machine's other load
comes and goes.

    .venv/bin/python bench/bench_live.py --keys 300       # key -> datagram, 20 clients

--keys N: bench_keys's W presses through the real window (Qt offscreen, the event filter,
the model, the link) onto the simulator (in this process, telemetry 50 Hz), N presses each
without a live server, with one and no client, with 20 npm clients subscribed to every
channel, and with the same 20 niced to 19 (clients on other machines, their own decoding out
of the console's way); p50/p99 of press -> the datagram leaving the link (its DatagramSent
time: key -> datagram, the issue's figure) and of press -> the RCP the simulator read (the
simulator is a thread of this process, so this one also waits for its GIL).
"""

from __future__ import annotations

import argparse
import bisect
import os
import resource
import sys
import time
from collections.abc import Callable
from typing import Any

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from common import percentile

from ocu.console.model import ConsoleModel
from ocu.hardware.registry import HARDWARE
from ocu.headless import HeadlessConsole
from ocu.link.live import UdpLink
from ocu.live.options import serve_console
from ocu.live.server import LiveServer
from ocu.priority import DEFAULT_NICE, raise_priority
from ocu.profile import RobotProfile, load_profile
from ocu.record import schemas as s
from ocu.records import DatagramSent, LinkEvent
from ocu.sim.launcher import SimulatorProcess
from ocu.sim.simulator import RobotSimulator
from tests.live.node_client import NodeClient, count


def cpu_s(server: LiveServer | None = None) -> float:
    """This process's CPU seconds, with the live relay's (the server's own process)."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    total = usage.ru_utime + usage.ru_stime
    pid = getattr(server, "relay_pid", None)  # an older tree serves in this process
    if pid is not None:
        from bench_live_console import process_cpu_s

        total += process_cpu_s(pid)
    return total


class SendGaps:
    """The gaps between the link's datagrams (its loop's health: the operator's commands)."""

    def __init__(self) -> None:
        self.gaps_ms: list[float] = []
        self._last: float | None = None

    def __call__(self, event: LinkEvent) -> None:
        if isinstance(event, DatagramSent):
            if self._last is not None:
                self.gaps_ms.append((event.sent_at - self._last) * 1000.0)
            self._last = event.sent_at

    def take(self) -> str:
        gaps, self.gaps_ms = self.gaps_ms, []
        return f"send gaps p99 {percentile(gaps, 99):5.1f} ms max {max(gaps):5.1f} ms"


def count_published(n: int) -> Callable[[list[dict[str, Any]]], bool]:
    """A predicate: the client has published its n-th message."""
    return lambda events: any(event.get("n") == n for event in events)


def teleop(profile: RobotProfile, count_n: int) -> None:
    """Client-published Twist -> the simulator's datagram (module docstring)."""
    sim = RobotSimulator(profile, telemetry_hz=50.0, video_fps=0.0)
    sim.start()
    hardware = HARDWARE.create("engineer", profile, f"{sim.address[0]}:{sim.address[1]}")
    console = HeadlessConsole(ConsoleModel(profile), hardware)
    server = LiveServer(profile, "127.0.0.1", 0, control=True)
    server.start()
    serve_console(server, console.manager)
    console.start()
    spec: dict[str, object] = {"topic": "/cmd_vel", "encoding": "cdr"}
    spec["schemaName"] = "geometry_msgs/msg/Twist"
    spec |= {"rateHz": 1.0, "count": count_n, "linear": 0.3, "angular": 0.0}
    client = NodeClient(f"ws://127.0.0.1:{server.address[1]}", topics=[], publish=spec)
    latencies_ms = []
    try:
        for n in range(1, count_n + 1):
            moving = sim.wait_until(lambda s: s.commanded_velocities.get("drive_linear", 0) > 0, 10)
            seen_ms = time.time() * 1000.0
            assert moving
            assert client.wait(count_published(n), 10.0)
            latencies_ms.append(seen_ms - client.of("published")[n - 1]["local_ms"])
            assert sim.wait_until(lambda s: s.commanded_velocities.get("drive_linear", 0) == 0, 5)
    finally:
        client.close()
        server.stop()
        console.stop()
        sim.stop()
    print(
        f"client Twist -> datagram: p50 {percentile(latencies_ms, 50):.1f} ms "
        f"p99 {percentile(latencies_ms, 99):.1f} ms ({len(latencies_ms)} from rest, 1 Hz)"
    )


def stream(profile: RobotProfile, count_n: int) -> None:
    """A client's Twist stream (10 Hz, alternating speeds) -> the simulator's datagram."""
    sim = RobotSimulator(profile, telemetry_hz=50.0, video_fps=0.0)
    sim.start()
    hardware = HARDWARE.create("engineer", profile, f"{sim.address[0]}:{sim.address[1]}")
    console = HeadlessConsole(ConsoleModel(profile), hardware)
    server = LiveServer(profile, "127.0.0.1", 0, control=True)
    server.start()
    serve_console(server, console.manager)
    console.start()
    speeds = (0.2, 0.3)
    axis = profile.channels["drive_linear"].axis
    spec: dict[str, object] = {"topic": "/cmd_vel", "encoding": "cdr"}
    spec |= {"schemaName": "geometry_msgs/msg/Twist", "rateHz": 10.0, "count": count_n}
    spec |= {"linear": speeds[0], "angular": 0.0, "alternate": speeds[1]}
    client = NodeClient(f"ws://127.0.0.1:{server.address[1]}", topics=[], publish=spec)
    try:
        assert client.wait(count_published(count_n), count_n / 10.0 + 60.0)
        assert sim.wait_until(lambda s: s.commanded_velocities.get("drive_linear", 0) == 0, 5)
    finally:
        client.close()
        server.stop()
        console.stop()
        sim.stop()
    received = sim.received_commands()
    times = [r.time_s for r in received]
    wall_minus_mono = time.time() - time.monotonic()
    latencies_ms = []
    # From the second message on, each asks for a new speed: its latency is from its send to
    # the first datagram whose drive differs from the one on the wire when it was sent.
    for event in client.of("published")[1:]:
        sent_s = event["local_ms"] / 1000.0 - wall_minus_mono
        i = bisect.bisect_left(times, sent_s)
        if i == 0:
            continue
        before = received[i - 1].packet.axes[axis]
        changed = next((r for r in received[i:] if r.packet.axes[axis] != before), None)
        if changed is not None:
            latencies_ms.append((changed.time_s - sent_s) * 1000.0)
    print(
        f"client Twist stream -> datagram: p50 {percentile(latencies_ms, 50):.1f} ms "
        f"p99 {percentile(latencies_ms, 99):.1f} ms max {max(latencies_ms):.1f} ms "
        f"({len(latencies_ms)} of {count_n}, 10 Hz)"
    )


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--clients", type=int, nargs="+", default=[1, 5, 20])
    parser.add_argument("--phase-s", type=float, default=10.0)
    parser.add_argument("--teleop", type=int, metavar="N", help="measure client Twist -> datagram")
    parser.add_argument("--stream", type=int, metavar="N", help="a 10 Hz Twist stream -> datagram")
    parser.add_argument("--console", type=int, metavar="N", help="the console's CPU, N clients")
    parser.add_argument("--keys", type=int, metavar="N", help="key -> datagram with 20 clients")
    args = parser.parse_args()
    profile = load_profile()
    print(f"priority: {raise_priority(DEFAULT_NICE).text} (as the console asks)")
    if args.teleop:
        teleop(profile, args.teleop)
        return 0
    if args.stream:
        stream(profile, args.stream)
        return 0
    if args.console:
        from bench_live_console import console_cpu

        console_cpu(profile, args.console, args.phase_s)
        return 0
    if args.keys:
        from bench_live_console import keys

        keys(profile, args.keys)
        return 0
    cameras = [s.camera_topic(name) for name in profile.link.camera_names]
    topics = [s.JOINT_STATES, "/tf", *cameras]
    with SimulatorProcess(None, ["--extended", "--telemetry-hz", "50"]) as sim:
        server = LiveServer(profile, "127.0.0.1", 0)
        server.start()
        link = UdpLink(profile, sim.address, gui_alive_timeout_s=None, extension=True)
        server.attach(link)
        gaps = SendGaps()
        link.subscribe(gaps)
        link.start()
        link.set_velocities(waist=0.2)
        url = f"ws://127.0.0.1:{server.address[1]}"
        try:
            time.sleep(2.0)  # a benchmark's settling time, not synchronisation
            start = cpu_s(server)
            time.sleep(args.phase_s)
            base = (cpu_s(server) - start) / args.phase_s * 100.0
            print(f"no client: CPU {base:.0f} % of a core, {gaps.take()}")
            for n in args.clients:
                clients = [NodeClient(url, topics=topics, brief=True) for _ in range(n)]
                try:
                    for client in clients:
                        assert client.wait(count(s.JOINT_STATES, 10), 60.0)
                    marks = [len(c.events) for c in clients]
                    gaps.take()
                    start = cpu_s(server)
                    time.sleep(args.phase_s)
                    cpu = (cpu_s(server) - start) / args.phase_s * 100.0
                    latencies_ms = []
                    frames = 0
                    for client, mark in zip(clients, marks, strict=True):
                        events = client.events[mark:]
                        for event in events:
                            if event["event"] != "message":
                                continue
                            if event["topic"] == s.JOINT_STATES:
                                latencies_ms.append(event["local_ms"] - event["receive_ns"] / 1e6)
                            elif event["topic"] in cameras:
                                frames += 1
                    dropped = sum(c.dropped for c in server.stats().clients)
                finally:
                    for client in clients:
                        client.close()
                print(
                    f"{n:2d} clients: telemetry->client p50 {percentile(latencies_ms, 50):6.2f} ms"
                    f"  p99 {percentile(latencies_ms, 99):6.2f} ms  ({len(latencies_ms)} msgs)"
                    f"  camera frames/s per client {frames / args.phase_s / n:5.1f}"
                    f"  CPU {cpu:.0f} % (+{cpu - base:.0f})  dropped {dropped}  {gaps.take()}"
                )
        finally:
            link.shutdown()
            server.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
