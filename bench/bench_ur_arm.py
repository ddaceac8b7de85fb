"""The UR5e's arm through the console against the UR simulator, at 0 and 50 ms one-way latency.

Ground truth: the simulator's joint angles at every control cycle (its arm's step wrapped),
through the UR's URDF (`ArmKinematics`, the console's chain; UR's DH to 1e-6).

- **Straight 10 cm Cartesian jog**: the console's control core (`HeadlessConsole`,
  `ConsoleModel(ur_robot_profile(ur5e))`, the `ur-sim` plug-in, control at 50 Hz as the
  window) jogs tool0 10 cm along -y in the base frame at the default 50 mm/s, the tool
  pointing down (tests/console/test_ur_arm.py's start). The largest distance of the true
  tool0 from the line, from the key press until the arm is at rest. Baseline in the same
  run: a resolved-rate jog on the last reading (J⁺ v from the newest telemetry, no
  prediction, no feedback), set as typed joint velocities through the same console model
  every control period (bench/bench_arm.py's baseline).
- **3-joint move**: shoulder_lift +30°, elbow -35°, wrist_1 +25° at once, through the arm's
  synchronized move (`ArmConsole.move_to_joints`, speedj with the delay-aware feedback). Per
  joint: overshoot past its goal (°, the largest over the joints), when it arrived (stays
  within 0.1° of where it comes to rest, controller time) and the spread of those arrivals
  (s); the final error. Also with the round trip told to the console (`DelayTold`: the
  simulator's known round trip, against UrLink's own measurement). Against, in the same run:
  the console's own plan streamed as `servoj` at
  125 Hz by a minimal client writing URScript on the realtime port itself (UrLink sends only
  speedj and stopj), lookahead 0.1 s (default) and 0.03 s (seed 004's figure 6).
- **speedj vs servoj, command -> arm moving** (seed 004's figures 3-7): the minimal client
  moves wrist 3 by 0.5 rad on a trapezoid (0.5 rad/s, 5 rad/s²), streamed at 125 Hz either
  as speedj (the profile's velocities, a = 15, t = 0.06: open loop, as seed 004's figure 3)
  or as servoj (the positions). First motion: first send -> the simulator's wrist 3 moving
  (wall). Lag: how long after the trajectory the arm reaches the same angle, median over the
  move (wall; seed 004 saw ~124 ms for threaded servoj on firmware 1.8, little for speedj).

    nice -n 5 .venv/bin/python bench/bench_ur_arm.py [--runs 2]   # ~1.5 min a run, 2 cores
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import logging
import math
import os
import socket
import statistics
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from typing import Any, TypeVar

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from ocu.console.channels import Source
from ocu.console.model import ConsoleModel
from ocu.hardware.ur import SimulatedUr, simulated
from ocu.headless import HeadlessConsole
from ocu.kinematics.arm import ArmKinematics
from ocu.kinematics.numeric import damped_pseudo_inverse
from ocu.kinematics.trajectory import SyncMove, plan
from ocu.link import ur as ur_link
from ocu.link.ur_wire import telemetry_frame
from ocu.profile import RobotProfile
from ocu.profile.ur import UrArmProfile, load_ur_profile
from ocu.profile.ur_robot import ur_robot_profile
from ocu.protocol.ur import script
from ocu.records import LinkState, TelemetryFrame
from ocu.sim.ur import UrSimulator

ARM = "ur5e"
# The tool pointing down, tool0 under the shoulder's side (tests/console/test_ur_arm.py).
START = (0.0, -1.57, 1.57, -1.57, -1.57, -0.2635)
JOG_M = 0.10
MOVE_DEG = {"shoulder_lift_joint": 30.0, "elbow_joint": -35.0, "wrist_1_joint": 25.0}
ARRIVED_RAD = math.radians(0.1)
CONTROL_PERIOD_S = 0.02  # the window's control rate (ocu.core.manager.DEFAULT_RATE_HZ)
STREAM_PERIOD_S = 0.008  # 125 Hz, seed 004's streaming rate
DEADLINE_S = 20.0
LATENCIES_MS = (0.0, 50.0)
T = TypeVar("T")
REACTIONS = 5  # trials of each streamed kind per run
JOG_METHODS = {
    "ours": "console (the round trip UrLink measures)",
    "told": "console, round trip told (bench stand-in)",
    "baseline": "resolved rate on the last reading",
}
MOVE_METHODS = (
    "speedj + feedback (console)",
    "speedj + feedback, round trip told",
    "servoj 125 Hz, lookahead 0.1 s",
    "servoj 125 Hz, lookahead 0.03 s",
)


def wait_for(condition: Callable[[], bool], what: str, poll_s: float = 0.005) -> float:
    """Wait for `condition`; the monotonic time it was first seen true."""
    deadline = time.monotonic() + DEADLINE_S
    while not condition():
        if time.monotonic() > deadline:
            raise RuntimeError(f"not {what} within {DEADLINE_S} s")
        time.sleep(poll_s)
    return time.monotonic()


@dataclass(frozen=True)
class Sample:
    wall: float  # monotonic s when read
    time_s: float  # controller time
    q: tuple[float, ...]
    qd: tuple[float, ...]


class Recorder:
    """Every control cycle of the simulator's arm (its step wrapped: none polled, none missed)."""

    def __init__(self, sim: UrSimulator) -> None:
        self.samples: list[Sample] = []
        arm = sim.arm
        step = arm.step

        def recorded(dt: float, now_s: float) -> None:
            step(dt, now_s)
            self.samples.append(Sample(time.monotonic(), now_s, tuple(arm.q), tuple(arm.qd)))

        setattr(arm, "step", recorded)  # noqa: B010 (a bench's probe on one instance)

    def since(self, wall: float) -> list[Sample]:
        return [s for s in list(self.samples) if s.wall >= wall]


def at_rest(sim: UrSimulator) -> bool:
    return all(abs(v) < 1e-9 for v in sim.snapshot().qd)


# ---- through the console -----------------------------------------------------------------------


class DelayTold:
    """A bench-only stand-in for the round-trip measurement UrLink lacks: every telemetry frame
    carries the simulator's known round trip (2 x one-way + a cycle to take effect + the cycle
    by which q_actual lags), as ocu.link.delay measures it on the Engineer's link."""

    def __init__(self, latency_ms: float) -> None:
        self.delay_s = 2.0 * latency_ms / 1000.0 + 0.004
        self.original = telemetry_frame

    def __enter__(self) -> None:
        def told(*args: Any, **kwargs: Any) -> TelemetryFrame:
            return dataclasses.replace(self.original(*args, **kwargs), delay_s=self.delay_s)

        setattr(ur_link, "telemetry_frame", told)  # noqa: B010

    def __exit__(self, *exc: object) -> None:
        setattr(ur_link, "telemetry_frame", self.original)  # noqa: B010


class Console:
    """HeadlessConsole over the ur-sim plug-in (its simulator in this process), recorded."""

    def __init__(self, latency_ms: float) -> None:
        self.profile: RobotProfile = ur_robot_profile(load_ur_profile(ARM))
        hardware = simulated(self.profile, latency_ms=latency_ms, initial_q=START)
        assert isinstance(hardware, SimulatedUr)
        self.sim = hardware.simulator
        self.model = ConsoleModel(self.profile)
        self.headless = HeadlessConsole(self.model, hardware, control_period_s=CONTROL_PERIOD_S)
        arm = self.model.arm
        assert arm is not None, self.model.arm_error
        self.arm = arm
        self.kin: ArmKinematics = arm.kinematics
        self.messages: list[str] = []
        arm.events.message.connect(self.messages.append)
        self.recorder = Recorder(self.sim)
        self.headless.start()
        wait_for(lambda: self.headless.link.state is LinkState.CONNECTED, "connected")
        wait_for(lambda: self.headless.call(arm.tool_pose) is not None, "tool0 known")

    def tool(self, q: Sequence[float]) -> np.ndarray:
        return self.kin.tool_pose(np.asarray(q, dtype=float)).position

    def stopped(self) -> str:
        """Why the console stopped the arm's motion on its own (e.g. stale telemetry), or ""."""
        return next((m for m in self.messages if "stopped" in m), "")

    def close(self) -> None:
        self.headless.stop()


class Interruption(Exception):  # noqa: N818 (not an error: a retry)
    """The console stopped the motion on its own (the reason); the trial is run again."""


def line_deviation(console: Console, samples: list[Sample]) -> tuple[float, float]:
    """Largest distance of tool0 from the line along -y through its start; the travel."""
    origin = console.tool(samples[0].q)
    unit = np.array([0.0, -1.0, 0.0])
    worst = 0.0
    travel = 0.0
    for sample in samples:
        offset = console.tool(sample.q) - origin
        along = float(offset @ unit)
        travel = max(travel, along)
        worst = max(worst, float(np.linalg.norm(offset - along * unit)))
    return worst, travel


def retried(trial: Callable[[], T], interruptions: list[str]) -> T:
    """Run a trial until the console does not stop it on its own (5 tries); the reasons kept."""
    for _ in range(5):
        try:
            return trial()
        except Interruption as err:
            interruptions.append(str(err))
    raise RuntimeError(f"interrupted 5 times: {interruptions[-5:]}")


def jog(latency_ms: float, method: str) -> tuple[float, float]:
    """One 10 cm jog ("ours", "told": ours with the delay told, "baseline"): deviation, travel."""
    with DelayTold(latency_ms) if method == "told" else contextlib.nullcontext():
        return _jog(Console(latency_ms), method)


def _jog(console: Console, method: str) -> tuple[float, float]:
    try:
        arm, model = console.arm, console.model
        origin = console.tool(console.sim.snapshot().q)

        def travelled() -> float:
            return float(origin[1] - console.tool(console.sim.snapshot().q)[1])

        def done() -> bool:
            if method != "baseline" and not console.headless.call(lambda: arm.controller.active):
                raise Interruption(f"arm: jog stopped: {arm.status.reason}")
            return travelled() >= JOG_M

        started = time.monotonic()
        if method != "baseline":
            console.headless.call(lambda: arm.set_cartesian(True))
            console.headless.call(lambda: arm.jog_key_down("right", "y", -1))
            wait_for(done, "10 cm travelled")
            console.headless.call(lambda: arm.jog_key_up("right"))
        else:
            kin = console.kin
            twist = np.array([0.0, -arm.linear_speed_m_s, 0.0, 0.0])
            weights = np.array([1.0 / kin.length_scale_m] * 3 + [1.0])

            def step() -> None:
                q = kin.vector(model.robot.angles())
                jac = kin.task_jacobian(q) * weights[:, None]
                qd = damped_pseudo_inverse(jac, 0.02) * weights[None, :] @ twist
                model.set_velocities(
                    {c: float(v) for c, v in zip(arm.channels, qd, strict=True)}, Source.TEXT
                )

            while not done():
                if time.monotonic() - started > DEADLINE_S:
                    raise RuntimeError("the baseline jog did not travel 10 cm")
                console.headless.call(step)
                time.sleep(CONTROL_PERIOD_S)
            console.headless.call(lambda: model.set_velocities(dict.fromkeys(arm.channels, 0.0)))
        wait_for(lambda: at_rest(console.sim), "at rest")
        return line_deviation(console, console.recorder.since(started))
    finally:
        console.close()


# ---- the minimal URScript client (servoj and speedj written by hand) ---------------------------


class ScriptClient:
    """A bare realtime-port client: writes URScript lines; reads and drops what arrives."""

    def __init__(self, sim: UrSimulator) -> None:
        self.sock = socket.create_connection((sim.host, sim.ports["realtime"]), timeout=2.0)
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._thread = threading.Thread(target=self._drain, name="bench-drain", daemon=True)
        self._thread.start()

    def _drain(self) -> None:
        try:
            while self.sock.recv(65536):
                pass
        except OSError:
            pass

    def send(self, line: bytes) -> None:
        self.sock.sendall(line)

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self.sock.shutdown(socket.SHUT_RDWR)
        self._thread.join()
        self.sock.close()


def stream(client: ScriptClient, lines: Callable[[float], bytes | None]) -> float:
    """Send lines(t) every 8 ms (t from the first send) until it gives None; the start."""
    start = time.monotonic()
    tick = 0
    while True:
        line = lines(time.monotonic() - start)
        if line is None:
            return start
        client.send(line)
        tick += 1
        remaining = start + tick * STREAM_PERIOD_S - time.monotonic()
        if remaining > 0:
            time.sleep(remaining)


@dataclass(frozen=True)
class MoveResult:
    overshoot_deg: float
    spread_s: float
    final_deg: float
    arrived_s: float  # the last joint's arrival after the start (controller time)


def move_figures(
    samples: list[Sample], start_q: Sequence[float], goal: dict[int, float]
) -> MoveResult:
    """Overshoot, arrival spread, final error of the moving joints in `goal` (index -> rad)."""
    t0 = samples[0].time_s
    overshoot = 0.0
    arrivals = []
    final = 0.0
    for i, target in goal.items():
        direction = math.copysign(1.0, target - start_q[i])
        overshoot = max(overshoot, *((s.q[i] - target) * direction for s in samples))
        rest = samples[-1].q[i]
        final = max(final, abs(rest - target))
        arrived = t0
        for s in reversed(samples):
            if abs(s.q[i] - rest) > ARRIVED_RAD:
                arrived = s.time_s
                break
        arrivals.append(arrived - t0)
    return MoveResult(
        math.degrees(overshoot), max(arrivals) - min(arrivals), math.degrees(final), max(arrivals)
    )


def three_joint_move(latency_ms: float, told: bool) -> tuple[MoveResult, SyncMove]:
    """The console's synchronized move (speedj with feedback); its plan for the servoj runs."""
    with DelayTold(latency_ms) if told else contextlib.nullcontext():
        return _three_joint_move(Console(latency_ms))


def _three_joint_move(console: Console) -> tuple[MoveResult, SyncMove]:
    try:
        arm, kin = console.arm, console.kin
        goal = dict(zip(kin.joints, START, strict=True))
        for joint, degrees in MOVE_DEG.items():
            goal[joint] += math.radians(degrees)
        started = time.monotonic()
        console.headless.call(lambda: arm.move_to_joints("3 joints", goal))
        move = console.headless.call(lambda: arm.controller.move_plan)
        assert move is not None
        wait_for(lambda: not console.headless.call(lambda: arm.controller.active), "arrived")
        if console.stopped():
            raise Interruption(console.stopped())
        wait_for(lambda: at_rest(console.sim), "at rest")
        indices = {kin.joints.index(j): goal[j] for j in MOVE_DEG}
        return move_figures(console.recorder.since(started), START, indices), move
    finally:
        console.close()


def servoj_move(
    arm_profile: UrArmProfile, latency_ms: float, move: SyncMove, lookahead: float
) -> MoveResult:
    """The same plan streamed as servoj by the minimal client; the goal held until at rest."""
    with UrSimulator(arm_profile, ports=(0, 0, 0), latency_ms=latency_ms, initial_q=START) as sim:
        recorder = Recorder(sim)
        client = ScriptClient(sim)
        try:
            goal = [float(v) for v in move.goal]

            def line(t: float) -> bytes | None:
                if t > move.duration_s + 0.3 and (
                    t > move.duration_s + 5.0 or at_rest_near(sim, goal)
                ):
                    return None
                q, _ = move.sample(t)
                return script.servoj([float(v) for v in q], STREAM_PERIOD_S, lookahead, 300.0)

            started = stream(client, line)
            wait_for(lambda: at_rest(sim), "at rest")
            samples = recorder.since(started)
        finally:
            client.close()
    indices = {i: goal[i] for i in range(6) if abs(goal[i] - START[i]) > 1e-6}
    return move_figures(samples, START, indices)


def at_rest_near(sim: UrSimulator, goal: Sequence[float]) -> bool:
    snap = sim.snapshot()
    return all(abs(v) < 1e-4 for v in snap.qd) and all(
        abs(q - g) < ARRIVED_RAD / 10 for q, g in zip(snap.q, goal, strict=True)
    )


def reaction(arm_profile: UrArmProfile, latency_ms: float, kind: str) -> tuple[float, float]:
    """Wrist 3 by 0.5 rad streamed as speedj or servoj: first motion and lag (s, wall)."""
    move = plan([START[5]], [START[5] + 0.5], [0.5], [5.0])
    accel = arm_profile.max_acceleration_rad_s2
    with UrSimulator(arm_profile, ports=(0, 0, 0), latency_ms=latency_ms, initial_q=START) as sim:
        recorder = Recorder(sim)
        client = ScriptClient(sim)
        try:

            def line(t: float) -> bytes | None:
                if t > move.duration_s + 0.2:
                    return None
                q, qd = move.sample(t + STREAM_PERIOD_S)  # the first line asks for motion
                if kind == "speedj":
                    return script.speedj([*[0.0] * 5, float(qd[0])], accel, 0.06)
                return script.servoj([*START[:5], float(q[0])], STREAM_PERIOD_S, 0.1, 300.0)

            started = stream(client, line)
            wait_for(lambda: at_rest(sim), "at rest")
            samples = recorder.since(started)
        finally:
            client.close()
    first = next(s.wall for s in samples if abs(s.qd[5]) > 1e-9) - started
    # The lag: when the arm reached an angle minus when the trajectory did, 10 %-90 % of it.
    fine = np.linspace(0.0, move.duration_s, 2001)
    path = np.array([move.scalar(t)[0] for t in fine])
    lags = []
    for s in samples:
        share = (s.q[5] - START[5]) / 0.5
        if 0.1 <= share <= 0.9:
            # The lines run one period ahead of their send time (the first asks for motion).
            lags.append(s.wall - started - float(np.interp(share, path, fine)) + STREAM_PERIOD_S)
    return first, statistics.median(lags)


# ---- the run -----------------------------------------------------------------------------------


def spread(values: list[float], scale: float = 1.0, digits: int = 3) -> str:
    """min-max of the runs (or the one value)."""
    low, high = min(values) * scale, max(values) * scale
    return (
        f"{low:.{digits}f}"
        if high - low < 0.5 * 10**-digits
        else f"{low:.{digits}f}-{high:.{digits}f}"
    )


def median_max(values: list[float]) -> str:
    """median / max in ms, and n."""
    return f"{statistics.median(values) * 1000:.1f} / {max(values) * 1000:.1f} (n={len(values)})"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=2, help="repetitions of everything")
    args = parser.parse_args()
    logging.basicConfig(level=logging.CRITICAL)
    arm_profile = load_ur_profile(ARM)
    print(f"UR5e simulator (5.10, 500 Hz), {args.runs} runs, load {os.getloadavg()[0]:.1f}")
    interruptions: list[str] = []
    for latency in LATENCIES_MS:
        print(f"\n== {latency:g} ms one-way latency")
        jogs: dict[str, list[tuple[float, float]]] = {m: [] for m in JOG_METHODS}
        moves: dict[str, list[MoveResult]] = {m: [] for m in MOVE_METHODS}
        reactions: dict[str, list[tuple[float, float]]] = {"speedj": [], "servoj": []}
        for _ in range(args.runs):
            for method in JOG_METHODS:
                jogs[method].append(retried(partial(jog, latency, method), interruptions))
            for told in (False, True):
                result, move = retried(partial(three_joint_move, latency, told), interruptions)
                moves[MOVE_METHODS[int(told)]].append(result)
            for index, lookahead in ((2, 0.1), (3, 0.03)):
                moves[MOVE_METHODS[index]].append(
                    servoj_move(arm_profile, latency, move, lookahead)
                )
            for kind, figures in reactions.items():
                figures.extend(reaction(arm_profile, latency, kind) for _ in range(REACTIONS))
        print("  10 cm jog, largest deviation of the true tool0 from the line (mm) [travel mm]")
        for method, rows in jogs.items():
            print(f"    {JOG_METHODS[method]:<44} {spread([r[0] for r in rows], 1000)} "
                  f"[{spread([r[1] for r in rows], 1000, 0)}]")  # fmt: skip
        print(f"  3-joint move (plan {move.duration_s:.2f} s): overshoot °, arrival spread s, "
              "final error °, last joint arrived s")  # fmt: skip
        for method, results in moves.items():
            print(
                f"    {method:<44} {spread([r.overshoot_deg for r in results])} "
                f"{spread([r.spread_s for r in results])} {spread([r.final_deg for r in results])} "
                f"{spread([r.arrived_s for r in results], digits=2)}"
            )
        print(
            "  wrist 3 by 0.5 rad: command -> moving; lag behind the trajectory (median / max ms)"
        )
        for kind, pairs in reactions.items():
            print(f"    {kind:<44} {median_max([p[0] for p in pairs])}; "
                  f"{median_max([p[1] for p in pairs])}")  # fmt: skip
        print(f"  (load now {os.getloadavg()[0]:.1f})")
    print(f"\nTrials the console stopped on its own and that were run again: {len(interruptions)}")
    for reason in interruptions:
        print(f"  {reason}")


if __name__ == "__main__":
    main()
