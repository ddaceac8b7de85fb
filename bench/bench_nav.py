"""Driving with a map, measured in the simulator: seed 002's experiment and its safety zones.

    python bench/bench_nav.py            # all three parts
    python bench/bench_nav.py ellipse    # the ellipse of eq. 6.1 at 0 / 10 / 26 % loss
    python bench/bench_nav.py zones      # 50 full-speed drives at walls, zones on and off
    python bench/bench_nav.py odometry   # drift after a 10 m square against ground truth
    python bench/bench_nav.py gui        # what the map and the zones cost the GUI thread

Everything runs the real console model (ocu.headless) over a real UDP link to the real
simulator with its fault layer; ground truth is the simulator's pose. Each part prints its
baseline from the same run: open-loop feed-forward for the ellipse, the zones off for the
drives, dead reckoning from the commands alone for odometry.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import math
import random
import statistics
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TypeVar

import numpy as np

from ocu.console.model import ConsoleModel
from ocu.control.drive import DriveBounds, scale_drive
from ocu.hardware.engineer import engineer_component
from ocu.headless import HeadlessConsole
from ocu.link.live import UdpLink
from ocu.nav.geometry import Pose
from ocu.nav.odometry import Odometry
from ocu.nav.tracking import Trajectory, ellipse
from ocu.nav.world import World, load_world
from ocu.profile import RobotProfile, load_profile
from ocu.protocol.mapping import scan_frame
from ocu.records import CommandSent, LinkEvent, LinkState, TelemetryFrame
from ocu.sim.faults import FaultConfig
from ocu.sim.simulator import RobotSimulator, SimState, StateRecorder

T = TypeVar("T")
LINEAR, TURN = "drive_linear", "drive_turn"
TELEMETRY_HZ = 10.0
FIELD = FaultConfig(latency_ms=60.0, jitter_ms=30.0, loss=0.1)
IDEAL_ELLIPSE_S = 40.0
# The tracks skid in turns: the chassis turns this much less than its belts say.
SLIP = 0.08
# A loaded machine can starve the console's thread past the link's 0.5 s watchdog, which then
# zeroes the motion (as it must); such a run says nothing about the controller and is repeated.
ATTEMPTS = 4


class StarvedError(RuntimeError):
    """The link's watchdog stopped the run: the console's thread was starved."""


def watch_starvation(headless: HeadlessConsole) -> list[str]:
    """Messages of the link's watchdog, collected while the run goes on."""
    starved: list[str] = []

    def on_message(text: str) -> None:
        if "silent for" in text or "stalled for" in text:
            starved.append(text)

    headless.call(lambda: headless.model.events.message.connect(on_message))
    return starved


def attempts(run: Callable[[], T]) -> tuple[T, int]:
    """The first run the watchdog did not stop, and how many were repeated."""
    for attempt in range(ATTEMPTS):
        try:
            return run(), attempt
        except StarvedError:
            continue
    raise StarvedError(f"the machine starved every one of {ATTEMPTS} runs")


def wait(condition: Callable[[], bool], timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            raise TimeoutError(what)
        time.sleep(0.02)


@contextmanager
def console(
    profile: RobotProfile,
    *,
    console_profile: RobotProfile | None = None,
    world: World | None = None,
    faults: FaultConfig | None = None,
    extended: bool = True,
    telemetry_hz: float = TELEMETRY_HZ,
    turn_slip: float = 0.0,
    seed: int = 1,
) -> Iterator[tuple[RobotSimulator, HeadlessConsole]]:
    """A simulator (cameras off) and a headless console connected to it."""
    sim = RobotSimulator(
        profile,
        extended=extended,
        world=world,
        telemetry_hz=telemetry_hz,
        video_fps=0.0,
        faults=faults,
        seed=seed,
        turn_slip=turn_slip,
    )
    if sim.extension is not None:
        for camera in range(len(profile.link.camera_names)):
            sim.extension.stop_camera(camera)
    sim.start()
    model = ConsoleModel(console_profile or profile)
    headless = HeadlessConsole(
        model,
        engineer_component(UdpLink(profile, sim.address, extension=extended), extension=extended),
    )
    headless.start()
    try:
        wait(
            lambda: headless.call(lambda: model.robot.link_state) is LinkState.CONNECTED,
            10.0,
            "link",
        )
        wait(lambda: headless.call(lambda: not model.nav.estimate().stale), 10.0, "odometry")
        yield sim, headless
    finally:
        headless.stop()
        sim.stop()


def cross_track_m(samples: list[SimState], reference: Trajectory) -> np.ndarray:
    """Distance of each true position from the reference path (its nearest point)."""
    dense = reference.points()
    # Finer than the reference's samples: interpolate ten points per segment.
    fine = np.concatenate(
        [dense[:-1] + (dense[1:] - dense[:-1]) * f for f in np.linspace(0, 1, 10, endpoint=False)]
    )
    positions = np.array([s.pose[:2] for s in samples])
    distances = np.linalg.norm(positions[:, None, :] - fine[None, :, :], axis=-1)
    return np.asarray(distances.min(axis=1))


# ---- the ellipse -------------------------------------------------------------------------


@dataclass
class EllipseRun:
    loss: float
    completion_s: float
    rms_m: float
    max_m: float
    end_m: float
    message: str


def ellipse_closed_loop(profile: RobotProfile, loss: float, seed: int) -> EllipseRun:
    faults = FaultConfig(loss=loss, latency_ms=20.0, jitter_ms=10.0)
    with console(profile, faults=faults, seed=seed, turn_slip=SLIP) as (sim, headless):
        model = headless.model
        messages: list[str] = []
        done = threading.Event()

        def on_assist(kind: str | None, text: str) -> None:
            if kind is None:
                messages.append(text)
                done.set()

        headless.call(lambda: model.events.assist_changed.connect(on_assist))
        starved = watch_starvation(headless)
        start = headless.call(lambda: model.nav.estimate().pose)
        reference = ellipse(start)
        recorder = StateRecorder(sim)
        started = time.monotonic()
        headless.call(model.start_ellipse)
        done.wait(120.0)
        completion = time.monotonic() - started
        recorder.stop()
        if starved:
            raise StarvedError(starved[0])
        samples = [s for s in recorder.samples if s.time_s >= sim.state().time_s - completion]
    end_text = messages[-1] if messages else "no end"
    return ellipse_run(loss, completion, samples, reference, start, end_text=end_text)


def ellipse_run(
    loss: float,
    completion: float,
    samples: list[SimState],
    reference: Trajectory,
    start: Pose,
    *,
    end_text: str,
) -> EllipseRun:
    """The errors of one run of the ellipse against its reference path."""
    errors = cross_track_m(samples, reference)
    end = samples[-1].pose
    return EllipseRun(
        loss,
        completion,
        float(np.sqrt(np.mean(errors**2))),
        float(errors.max()),
        math.hypot(end[0] - start.x_m, end[1] - start.y_m),
        end_text,
    )


def ellipse_feed_forward(profile: RobotProfile, loss: float, seed: int) -> EllipseRun:
    """Baseline: the reference's own (v_r, ω_r) sent open loop, no feedback."""
    faults = FaultConfig(loss=loss, latency_ms=20.0, jitter_ms=10.0)
    linear, turn = (profile.channels[n] for n in (LINEAR, TURN))
    bounds = DriveBounds(linear.default_max, turn.default_max, linear.min_speed, turn.min_speed)
    with console(profile, faults=faults, seed=seed, turn_slip=SLIP) as (sim, headless):
        start = headless.call(lambda: headless.model.nav.estimate().pose)
        reference = ellipse(start)

        def drive(v: float, w: float) -> None:
            headless.model.set_velocities({LINEAR: v, TURN: w})

        starved = watch_starvation(headless)
        recorder = StateRecorder(sim)
        started = time.monotonic()
        while (elapsed := time.monotonic() - started) < reference.duration_s:
            state = reference.at(elapsed)
            v, w = scale_drive(state.linear_m_s, state.angular_rad_s, bounds)
            headless.call(functools.partial(drive, v, w))
            time.sleep(0.05)
        headless.call(lambda: headless.model.halt("baseline done"))
        completion = time.monotonic() - started
        time.sleep(0.3)
        recorder.stop()
        if starved:
            raise StarvedError(starved[0])
        samples = [s for s in recorder.samples if s.time_s >= sim.state().time_s - completion]
    return ellipse_run(loss, completion, samples, reference, start, end_text="open loop")


def bench_ellipse(profile: RobotProfile) -> None:
    print("The ellipse of seed 002 eq. 6.1 (3.6 m x 2 m, ideal 40 s), Samson b = 40, xi = 0.8;")
    print(f"extended robot, telemetry {TELEMETRY_HZ:g} Hz, IMU heading, 20 ms +- 10 ms each way,")
    print(f"tracks slipping {SLIP:.0%} in turns;")
    print("error = distance of the true position from the ideal path")
    print(
        f"{'loss':>5} {'mode':<13} {'time s':>7} {'vs 40 s':>8} {'RMS cm':>7} {'max cm':>7}"
        f" {'end cm':>7}"
    )
    for index, loss in enumerate((0.0, 0.10, 0.26)):
        for name, run in (("Samson", ellipse_closed_loop), ("feed-forward", ellipse_feed_forward)):
            result, repeated = attempts(functools.partial(run, profile, loss, 100 + index))
            note = f" (repeated {repeated}x: watchdog)" if repeated else ""
            print(
                f"{loss:5.0%} {name:<13} {result.completion_s:7.1f} "
                f"{result.completion_s / IDEAL_ELLIPSE_S:7.2f}x {result.rms_m * 100:7.1f} "
                f"{result.max_m * 100:7.1f} {result.end_m * 100:7.1f}   {result.message}{note}",
                flush=True,
            )


# ---- the safety zones --------------------------------------------------------------------


@dataclass
class Drive:
    collided: bool
    duration_s: float
    gap_m: float
    # The link's watchdog cut the drive short (a starved console thread on a loaded machine).
    starved: bool = False


def random_starts(world: World, profile: RobotProfile, count: int, seed: int) -> list[Pose]:
    """Free poses facing an obstacle 1-3.5 m beyond the footprint's front."""
    footprint = profile.navigation.footprint
    assert footprint is not None
    rng = random.Random(seed)
    x0, y0, x1, y1 = world.bounds_m()
    starts: list[Pose] = []
    while len(starts) < count:
        pose = Pose(rng.uniform(x0, x1), rng.uniform(y0, y1), rng.uniform(-math.pi, math.pi))
        if world.touching(footprint, pose) is not None:
            continue
        ahead = gap_ahead(world, footprint.front_m, footprint.half_width_m, pose)
        if 1.0 <= ahead <= 3.5:
            starts.append(pose)
    return starts


def gap_ahead(world: World, front_m: float, half_width_m: float, pose: Pose) -> float:
    """Free distance ahead of the footprint's front edge (three rays across its width)."""
    c, s = math.cos(pose.heading_rad), math.sin(pose.heading_rad)
    gaps = []
    for lateral in (-half_width_m, 0.0, half_width_m):
        origin = (pose.x_m - s * lateral, pose.y_m + c * lateral)
        ranges = world.ray_cast(origin, np.array([pose.heading_rad]), 20.0)
        gaps.append(float(ranges[0]) - front_m)
    return min(gaps)


def drive_at_walls(
    profile: RobotProfile, starts: list[Pose], zones: bool, world: World
) -> list[Drive]:
    navigation = profile.navigation
    footprint = navigation.footprint
    assert footprint is not None
    # Zones off: the console's profile has no footprint; the simulator's chassis is the same.
    console_profile = (
        profile
        if zones
        else dataclasses.replace(
            profile, navigation=dataclasses.replace(navigation, footprint=None)
        )
    )
    drives: list[Drive] = []
    with console(profile, console_profile=console_profile, world=world, faults=FIELD, seed=7) as (
        sim,
        headless,
    ):
        model = headless.model
        headless.call(lambda: model.set_max_velocity(LINEAR, profile.channels[LINEAR].hard_max))
        starved = watch_starvation(headless)
        for pose in starts:
            starved_before = len(starved)
            headless.call(lambda: model.halt("next drive"))
            time.sleep(0.2)
            sim.place(pose)
            time.sleep(0.3)  # a scan from here
            before = sim.state().collisions
            started = time.monotonic()
            headless.call(lambda: model.hotkey_down("W", LINEAR, 1))
            last, since = sim.state().pose, time.monotonic()
            while time.monotonic() - started < 20.0:
                time.sleep(0.05)
                state = sim.state()
                if math.dist(state.pose[:2], last[:2]) > 0.003:
                    last, since = state.pose, time.monotonic()
                elif time.monotonic() - since > 0.6:
                    break
            duration = since - started
            headless.call(lambda: model.hotkey_up("W"))
            state = sim.state()
            drives.append(
                Drive(
                    state.collisions > before,
                    duration,
                    gap_ahead(world, footprint.front_m, footprint.half_width_m, Pose(*state.pose)),
                    len(starved) > starved_before,
                )
            )
    return drives


def bench_zones(profile: RobotProfile, count: int) -> None:
    world = load_world("default")
    starts = random_starts(world, profile, count, seed=2024)
    top = profile.channels[LINEAR].hard_max
    print(f"Safety zones: {count} drives at full speed ({top:g} m/s) toward walls and boxes of the")
    print("default room from random poses 1-3.5 m away; 60 +- 30 ms each way, 10 % loss")
    print(
        f"{'zones':<6} {'collisions':>10} {'mean s':>7} {'max s':>6} {'gap cm':>7} "
        f"{'min gap cm':>10} {'cut short':>9}"
    )
    results = {}
    for zones in (True, False):
        drives = drive_at_walls(profile, starts, zones, world)
        results[zones] = drives
        durations = [d.duration_s for d in drives]
        gaps = [d.gap_m for d in drives]
        print(
            f"{'on' if zones else 'off':<6} {sum(d.collided for d in drives):>10d} "
            f"{statistics.mean(durations):7.2f} {max(durations):6.2f} "
            f"{statistics.mean(gaps) * 100:7.1f} {min(gaps) * 100:10.1f} "
            f"{sum(d.starved for d in drives):9d}",
            flush=True,
        )
    cost = statistics.mean(d.duration_s for d in results[True]) - statistics.mean(
        d.duration_s for d in results[False]
    )
    print(f"time the zones cost per drive (until the robot stood still): {cost:+.2f} s")
    print("cut short: drives the link's 0.5 s watchdog stopped (the console's thread starved)")


# ---- odometry ----------------------------------------------------------------------------


def bench_odometry(profile: RobotProfile) -> None:
    side_m, speed, turn = 2.5, 0.3, 0.5
    print(f"Odometry after a 10 m square ({side_m:g} m sides at {speed:g} m/s, 90° turns at")
    print(f"{turn:g} rad/s), tracks slipping {SLIP:.0%} in turns; error = |estimate - truth|")
    print(
        f"{'condition':<34} {'pos cm':>7} {'head °':>7} {'max cm':>7} {'2σ cm':>6}"
        f" {'commands-only cm':>16} {'°':>6}"
    )
    conditions = (
        ("vendor protocol, telemetry 1 Hz", False, 1.0, None),
        ("extension (IMU), telemetry 1 Hz", True, 1.0, None),
        ("extension, 1 Hz, 60±30 ms, 10 % loss", True, 1.0, FIELD),
        ("extension, telemetry 10 Hz", True, 10.0, None),
    )
    for name, extended, rate, faults in conditions:
        result = square_run(
            profile,
            extended=extended,
            rate_hz=rate,
            faults=faults,
            side_m=side_m,
            speed=speed,
            turn=turn,
        )
        print(f"{name:<34} {result}", flush=True)


def square_run(
    profile: RobotProfile,
    *,
    extended: bool,
    rate_hz: float,
    faults: FaultConfig | None,
    side_m: float,
    speed: float,
    turn: float,
) -> str:
    """One square: the console's odometry and the commands-only baseline against truth."""
    with console(
        profile, extended=extended, telemetry_hz=rate_hz, faults=faults, turn_slip=SLIP, seed=3
    ) as (sim, headless):
        model = headless.model
        # The same run's baseline: dead reckoning from the commands alone.
        baseline = Odometry(
            profile.track_width_m,
            profile.navigation.odometry,
            min_linear_m_s=profile.channels[LINEAR].min_speed,
            min_angular_rad_s=profile.channels[TURN].min_speed,
        )
        lock = threading.Lock()

        def on_event(event: LinkEvent) -> None:
            with lock:
                if isinstance(event, CommandSent):
                    command = event.command
                    baseline.on_command(
                        event.sent_at, command.velocity(LINEAR), command.velocity(TURN)
                    )
                elif isinstance(event, TelemetryFrame):
                    baseline.set_round_trip(event.delay_s)

        def drive(v: float, w: float) -> None:
            model.set_velocities({LINEAR: v, TURN: w})

        headless.link.subscribe(on_event)
        headless.call(model.reset_odometry)
        with lock:
            baseline.reset(time.monotonic())
        worst = 0.0
        for _side in range(4):
            for v, w, seconds in ((speed, 0.0, side_m / speed), (0.0, turn, math.pi / 2 / turn)):
                headless.call(functools.partial(drive, v, w))
                until = time.monotonic() + seconds
                while time.monotonic() < until:
                    time.sleep(0.1)
                    estimate = headless.call(model.nav.estimate)
                    worst = max(worst, math.dist(sim.state().pose[:2], estimate.pose[:2]))
        headless.call(lambda: drive(0.0, 0.0))
        time.sleep(2.0)  # the last readings arrive
        estimate = headless.call(model.nav.estimate)
        truth = sim.state().pose
        with lock:
            dead = baseline.estimate(time.monotonic()).pose
        headless.link.unsubscribe(on_event)
    error = math.dist(truth[:2], estimate.pose[:2])
    heading = math.degrees(abs(math.remainder(truth[2] - estimate.pose.heading_rad, math.tau)))
    dead_error = math.dist(truth[:2], (dead.x_m, dead.y_m))
    dead_heading = math.degrees(abs(math.remainder(truth[2] - dead.heading_rad, math.tau)))
    return (
        f"{error * 100:7.1f} {heading:7.1f} {max(worst, error) * 100:7.1f} "
        f"{2 * estimate.sigma_xy_m * 100:6.1f} {dead_error * 100:16.1f} {dead_heading:6.1f}"
    )


def bench_gui_cost(profile: RobotProfile, seconds: float = 10.0) -> None:
    """What driving with a map costs the GUI thread: a second of scans (10 Hz), control ticks
    (20 Hz) and map paints (10 Hz), timed on this thread; the baseline is the ticks alone."""
    import os

    os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    from PySide6.QtGui import QImage
    from PySide6.QtWidgets import QApplication

    from ocu.sim.rangefinder import RangeSensor
    from ocu.widgets.map_view import MapPanel

    app = QApplication.instance() or QApplication([])
    world = load_world("default")
    sensor = RangeSensor(world, seed=5)
    model = ConsoleModel(profile)
    model.hotkey_down("W", LINEAR, 1)
    panel = MapPanel(model)
    panel.resize(460, 420)
    image = QImage(panel.view.size(), QImage.Format.Format_RGB32)
    del app

    def run(with_map: bool) -> float:
        ticks = int(seconds * 20)
        started = time.process_time()
        for tick in range(ticks):
            now = time.monotonic()
            if with_map and tick % 2 == 0:
                pose = Pose(0.05 * tick / 20, 0.0, 0.0)
                model.on_scan(scan_frame(sensor.sweep(pose, 0), now, 0.0))
                panel.view.render(image)
            model.update(now)
        return (time.process_time() - started) / seconds

    baseline = run(False)
    with_map = run(True)
    print("GUI-thread cost of driving with a map (10 Hz scans with the grid, 20 Hz control")
    print("ticks with the zones, 10 Hz paints of a 460x420 map), offscreen:")
    print(
        f"  with the map {with_map * 100:.1f} % of a core; ticks alone {baseline * 100:.1f} %; "
        f"the map's share {(with_map - baseline) * 100:.1f} %"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "part", nargs="?", default="all", choices=("all", "ellipse", "zones", "odometry", "gui")
    )
    parser.add_argument("--drives", type=int, default=50, help="drives at walls (default 50)")
    args = parser.parse_args()
    profile = load_profile()
    if args.part in ("all", "ellipse"):
        bench_ellipse(profile)
    if args.part in ("all", "zones"):
        bench_zones(profile, args.drives)
    if args.part in ("all", "odometry"):
        bench_odometry(profile)
    if args.part in ("all", "gui"):
        bench_gui_cost(profile)


if __name__ == "__main__":
    main()
