"""The Arm dock over a UR: Cartesian jog and pose goals with the UR's URDF, the console's model
driving the simulated joints over a delayed link (tests/console/arm_rig.py)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from ocu.console.model import ConsoleModel
from ocu.control.arm import OK
from ocu.kinematics.arm import ArmError, ToolPose
from ocu.kinematics.rpy import angle_between
from ocu.profile import RobotProfile
from ocu.profile.ur import load_ur_profile
from ocu.profile.ur_robot import ur_robot_profile
from tests.console.arm_rig import Rig

# The tool pointing down with its x axis almost across the arm's plane: a pitch measured on
# tool0's x axis is ill-defined here (it jumps between 0° and ±180°), on its z axis it is -90°.
WRIST_DOWN = (0.0, -1.57, 1.57, -1.57, -1.57, -0.2635)


@pytest.fixture(scope="module")
def ur5e() -> RobotProfile:
    return ur_robot_profile(load_ur_profile("ur5e"))


def _start(profile: RobotProfile, values: tuple[float, ...]) -> dict[str, float]:
    assert profile.arm is not None
    return dict(zip(profile.arm.joints, values, strict=True))


def test_the_console_has_cartesian_control_of_a_ur(ur5e: RobotProfile) -> None:
    model = ConsoleModel(ur5e)
    assert model.arm_error == ""
    assert model.arm is not None
    assert model.arm.kinematics.joints == load_ur_profile("ur5e").joint_names
    assert model.arm.kinematics.chain.base == "base_link"
    assert model.arm.kinematics.chain.tip == "tool0"


def test_a_jog_moves_tool0_along_the_line_and_keeps_it_pointing_down(
    ur5e: RobotProfile, tmp_path: Path
) -> None:
    rig = Rig(ur5e, tmp_path, start=_start(ur5e, WRIST_DOWN))
    rig.arm.set_cartesian(True)
    start = rig.truth()
    assert start.pitch == pytest.approx(-math.pi / 2, abs=0.01)
    assert rig.arm.jog_key_down("right", "y", -1)  # across y = 0, under the shoulder
    trace = []
    for _ in range(80):  # 4 s at 5 cm/s
        rig.tick()
        trace.append(rig.position())
        assert rig.arm.status.level == OK, rig.arm.status
    assert rig.arm.jog_key_up("right")
    assert rig.arm_velocities() == {}
    rig.run(0.5)
    moved = rig.position() - start.position
    assert moved[1] == pytest.approx(-0.2, abs=0.01)
    unit = np.array([0.0, 1.0, 0.0])
    deviation = max(
        float(np.linalg.norm((p - start.position) - np.dot(p - start.position, unit) * unit))
        for p in trace
    )
    assert deviation < 0.001  # within 1 mm of the line (0.013 mm measured)
    assert rig.truth().pitch == pytest.approx(start.pitch, abs=math.radians(0.5))


@pytest.mark.parametrize(("axis", "column"), [("yaw", 2), ("roll", 0), ("pitch", 1)])
def test_a_turning_key_turns_tool0_about_its_own_axis_and_keeps_it_in_place(
    ur5e: RobotProfile, tmp_path: Path, axis: str, column: int
) -> None:
    # In the tool frame over a 50 ms link at 10 Hz: the tool turns about its own x, y or z
    # axis, tool0 stays where it is and the other two axes keep their line.
    rig = Rig(ur5e, tmp_path, start=_start(ur5e, WRIST_DOWN))
    rig.arm.set_cartesian(True)
    rig.arm.set_frame("tool")
    kin = rig.kinematics
    before = kin.tool_matrix(kin.vector(rig.robot.joints))
    assert rig.arm.jog_key_down("turn", axis, 1)
    trace = []
    for _ in range(40):  # 2 s at the turning speed
        rig.tick()
        trace.append(kin.tool_matrix(kin.vector(rig.robot.joints)))
        assert rig.arm.status.level == OK, rig.arm.status
    assert rig.arm.jog_key_up("turn")
    rig.run(0.5)
    after = kin.tool_matrix(kin.vector(rig.robot.joints))
    drift = max(float(np.linalg.norm(m[:3, 3] - before[:3, 3])) for m in trace)
    assert drift < 0.001  # tool0 stays within 1 mm while it turns
    turned = angle_between(before, after)
    assert turned > math.radians(20.0)
    # About its own axis: that axis keeps its direction.
    assert float(after[:3, column] @ before[:3, column]) > math.cos(math.radians(0.5))
    # Turning the other way brings it back.
    assert rig.arm.jog_key_down("back", axis, -1)
    for _ in range(40):
        rig.tick()
    assert rig.arm.jog_key_up("back")
    rig.run(0.5)
    assert angle_between(before, kin.tool_matrix(kin.vector(rig.robot.joints))) < 0.1 * turned


def test_a_four_joint_arm_refuses_the_turning_keys_with_a_reason(
    profile: RobotProfile, tmp_path: Path
) -> None:
    rig = Rig(profile, tmp_path)
    rig.arm.set_cartesian(True)
    assert not rig.arm.jog_key_down("Q", "yaw", 1)
    assert rig.arm_velocities() == {}
    assert "yaw needs an arm of six joints" in rig.messages[-1]


def test_a_pose_goal_reaches_position_and_pitch_and_keeps_the_tools_roll(
    ur5e: RobotProfile, tmp_path: Path
) -> None:
    rig = Rig(ur5e, tmp_path, start=_start(ur5e, WRIST_DOWN))
    kin = rig.kinematics
    before = kin.tool_matrix(kin.vector(rig.robot.joints))
    target = ToolPose(0.35, -0.25, 0.30, math.radians(-60.0))
    goal = rig.arm.preview_pose(target)
    assert goal.pose.position == pytest.approx(target.position, abs=1e-4)
    assert goal.pose.pitch == pytest.approx(target.pitch, abs=1e-3)
    rig.arm.accept()
    rig.run_until_idle()
    reached = rig.truth()
    assert reached.position == pytest.approx(target.position, abs=0.002)
    assert reached.pitch == pytest.approx(target.pitch, abs=math.radians(0.5))
    # The tool turned by the least that points it there: its x axis stays across the
    # pointing direction as much as it was (no spin about the tool's own axis).
    after = kin.tool_matrix(kin.vector(rig.robot.joints))
    pointing = after[:3, 2]
    turned_x = before[:3, 0] - (before[:3, 0] @ pointing) * pointing
    turned_x /= np.linalg.norm(turned_x)
    assert float(after[:3, 0] @ turned_x) > math.cos(math.radians(10.0))  # 4.1° measured


def test_a_whole_pose_is_solved_for_a_ur_and_refused_for_the_engineer(
    ur5e: RobotProfile, profile: RobotProfile
) -> None:
    model = ConsoleModel(ur5e)
    assert model.arm is not None
    kin = model.arm.kinematics
    rng = np.random.default_rng(4)
    current = np.array(WRIST_DOWN)
    for _ in range(5):
        wanted = current + rng.uniform(-0.6, 0.6, 6)
        target = kin.tool_matrix(wanted)
        q = kin.solve_matrix(target, current=current)
        reached = kin.tool_matrix(q)
        assert np.linalg.norm(reached[:3, 3] - target[:3, 3]) < 1e-4
        turn = reached[:3, :3].T @ target[:3, :3]
        assert math.degrees(math.acos(np.clip((np.trace(turn) - 1.0) / 2.0, -1.0, 1.0))) < 0.1
    engineer = ConsoleModel(profile)
    assert engineer.arm is not None
    with pytest.raises(ArmError, match="a whole pose needs six joints"):
        engineer.arm.kinematics.solve_matrix(np.eye(4))
