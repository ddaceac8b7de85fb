"""Cartesian jogging of the xArm 1S through the console's control core (HeadlessConsole) and
the xarm-sim plug-in: the true tool0 (the simulated servos' shafts through the xArm's URDF)
follows the line, and stops after the release; with the field's latency, garbage and noise.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
import pytest

from ocu.console.arm import ArmConsole
from ocu.console.model import ConsoleModel
from ocu.hardware.xarm import SimulatedXarm
from ocu.headless import HeadlessConsole
from ocu.kinematics.arm import ToolPose
from ocu.link.xarm import XarmLink
from ocu.profile.xarm import XarmProfile, load_xarm_profile
from ocu.profile.xarm_robot import xarm_robot_profile
from ocu.records import LinkState
from ocu.sim.xarm import XarmSimulator

DEADLINE_S = 20.0
JOG_M = 0.02
ARM_JOINTS = ("base", "shoulder", "elbow", "wrist_pitch")
# A bent arm reaching forward (URDF angles): well away from the straight-up singularity.
START_DEG = {"base": 0.0, "shoulder": 30.0, "elbow": 60.0, "wrist_pitch": 40.0}


def wait_for(check: Callable[[], bool], what: str) -> None:
    deadline = time.monotonic() + DEADLINE_S
    pause = threading.Event()
    while not check():
        if time.monotonic() > deadline:
            raise AssertionError(f"not {what} within {DEADLINE_S} s")
        pause.wait(0.005)


@dataclass
class Rig:
    arm: XarmProfile
    sim: XarmSimulator
    headless: HeadlessConsole
    console_arm: ArmConsole

    def true_tool(self) -> np.ndarray:
        positions = self.sim.snapshot().positions
        q = [
            self.arm.angle_rad(self.arm.joint(name), positions[self.arm.joint(name).servo])
            for name in ARM_JOINTS
        ]
        return self.console_arm.kinematics.tool_pose(np.array(q)).position


def rig(**faults: float) -> Iterator[Rig]:
    arm = load_xarm_profile("xarm1s")
    profile = xarm_robot_profile(arm)
    initial = {
        arm.joint(name).servo: arm.raw_units(arm.joint(name), math.radians(deg))
        for name, deg in START_DEG.items()
    }
    sim = XarmSimulator(arm, initial=initial, seed=4, **faults)  # type: ignore[arg-type]
    hardware = SimulatedXarm(sim, XarmLink(arm, sim.start(), profile=profile))
    model = ConsoleModel(profile)
    headless = HeadlessConsole(model, hardware, control_period_s=0.02)
    console_arm = model.arm
    assert console_arm is not None, model.arm_error
    headless.start()
    try:
        wait_for(lambda: headless.link.state is LinkState.CONNECTED, "connected")
        wait_for(lambda: headless.call(console_arm.tool_pose) is not None, "tool0 known")
        yield Rig(arm, sim, headless, console_arm)
    finally:
        headless.stop()


@pytest.fixture
def clean() -> Iterator[Rig]:
    yield from rig()


@pytest.fixture
def field() -> Iterator[Rig]:
    yield from rig(latency_ms=30.0, garbage_rate=0.2, noise_units=1.0)


def jog_20_mm(setup: Rig) -> tuple[float, float]:
    """Jog tool0 along -y until it has gone 20 mm, release, wait for rest: the largest
    distance from the line and the travel (m)."""
    arm = setup.console_arm
    origin = setup.true_tool()
    samples: list[np.ndarray] = []
    done = threading.Event()

    def record() -> None:
        while not done.wait(0.005):
            samples.append(setup.true_tool())

    recorder = threading.Thread(target=record, name="test-recorder")
    recorder.start()
    try:
        setup.headless.call(lambda: arm.set_cartesian(True))

        def travelled() -> bool:
            return bool(origin[1] - setup.true_tool()[1] >= JOG_M)

        for _ in range(5):
            # The console may stop a jog on its own (a loaded machine's stall, a stale
            # reading): the key is pressed again, as an operator would, and the line is
            # measured over the whole path.
            setup.headless.call(lambda: arm.jog_key_down("right", "y", -1))
            wait_for(
                lambda: travelled() or not setup.headless.call(lambda: arm.controller.active),
                "20 mm travelled or the jog stopped",
            )
            setup.headless.call(lambda: arm.jog_key_up("right"))
            if travelled():
                break
        assert travelled(), f"the jog kept stopping: {arm.status.reason}"
        wait_for(
            lambda: all(abs(v) < 2.0 for v in setup.sim.snapshot().velocities.values()),
            "the servos at rest",
        )
    finally:
        done.set()
        recorder.join()
    unit = np.array([0.0, -1.0, 0.0])
    worst = travel = 0.0
    for point in samples:
        offset = point - origin
        along = float(offset @ unit)
        travel = max(travel, along)
        worst = max(worst, float(np.linalg.norm(offset - along * unit)))
    return worst, travel


def test_a_20_mm_cartesian_jog_follows_the_line(clean: Rig) -> None:
    deviation, travel = jog_20_mm(clean)
    # Measured: 0.6-2.3 mm off the line, 20.8-22.2 mm travelled (the release stops the
    # setpoints at once; the shafts of seed 003's lightly damped servos run on a little).
    assert deviation < 0.004
    assert JOG_M <= travel < JOG_M + 0.006


def test_a_jog_under_the_fields_conditions_still_stops(field: Rig) -> None:
    """30 ms each way, garbage before a fifth of the replies, 1 unit (0.24°) of noise on
    every reading: the jog goes and the release stops it (docs/xarm.md's figures)."""
    deviation, travel = jog_20_mm(field)
    assert deviation < 0.01  # measured 4.4-5.7 mm
    assert JOG_M <= travel < JOG_M + 0.015  # measured 23.9-28.7 mm


def pose_goal(setup: Rig) -> tuple[float, float]:
    """A pose goal from the start pose, through the Arm's preview and accept, until the
    servos rest: the true tool0's distance from the target (m) and its pitch error (rad)."""
    arm = setup.console_arm
    target = ToolPose(0.20, 0.08, 0.10, math.radians(-30.0))
    setup.headless.call(lambda: arm.preview_pose(target))
    setup.headless.call(arm.accept)
    wait_for(lambda: not setup.headless.call(lambda: arm.controller.active), "the goal done")
    wait_for(
        lambda: all(abs(v) < 0.5 for v in setup.sim.snapshot().velocities.values()),
        "the servos at rest",
    )
    positions = setup.sim.snapshot().positions
    q = [
        setup.arm.angle_rad(setup.arm.joint(name), positions[setup.arm.joint(name).servo])
        for name in ARM_JOINTS
    ]
    pose = arm.kinematics.tool_pose(np.array(q))
    error = float(np.linalg.norm(pose.position - np.array(target.position)))
    return error, abs(pose.pitch - target.pitch)


def test_a_pose_goal_is_reached(clean: Rig) -> None:
    # Measured 2.0-2.7 mm, 0.2-0.25°: streamed short moves under the console's position
    # control (one servo unit is 0.24°, about 1 mm at this reach).
    error, pitch_error = pose_goal(clean)
    assert error < 0.006  # a loaded machine's late control cycles cost accuracy
    assert pitch_error < math.radians(1.5)


def test_a_pose_goal_under_the_fields_conditions(field: Rig) -> None:
    error, pitch_error = pose_goal(field)  # measured 4.9-5.5 mm, 1.2-1.4°
    assert error < 0.012
    assert pitch_error < math.radians(3.0)
