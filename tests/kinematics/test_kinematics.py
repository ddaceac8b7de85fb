"""Kinematics without Qt: FK against hand-computed and DH poses, analytic and numeric IK round
trips on the Engineer, a UR5-like and a Panda-like arm, Jacobians against finite differences."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest

from ocu.kinematics.analytic import ELBOW_DOWN, ELBOW_UP, UnreachableError, YawPitchArm
from ocu.kinematics.arm import ArmError, ArmKinematics, ToolPose
from ocu.kinematics.chain import Chain, ChainError
from ocu.kinematics.numeric import IkError, solve
from ocu.model.tree import transform
from ocu.model.urdf import load_urdf
from ocu.profile import RobotProfile

DATA = Path(__file__).parent / "data"
Array = npt.NDArray[np.float64]


@pytest.fixture(scope="module")
def arm(profile: RobotProfile) -> ArmKinematics:
    assert profile.arm is not None
    return ArmKinematics(load_urdf(meshes=False), profile.arm)


def test_engineer_fk_matches_a_hand_computation(arm: ArmKinematics) -> None:
    """Waist 90°, shoulder 30°, elbow 60°, neck 0, worked out on paper from the URDF:

    shoulder axis at (-0.12, 0, 0.24 + 0.13); in the arm's plane (now along +y) the upper arm
    (0.42) rises 30°, the forearm (0.38) points 30° down, the tool offset (0.07 + 0.175 along,
    -0.04 across) turns by -30°: u = 0.42 cos30 + 0.38 cos30 + 0.245 cos30 - 0.04 sin30 =
    0.88498, w = 0.42 sin30 - 0.38 sin30 - 0.245 sin30 - 0.04 cos30 = -0.13714.
    """
    q = np.radians([90.0, 30.0, 60.0, 0.0])
    pose = arm.tool_pose(q)
    c30, s30 = math.cos(math.radians(30)), math.sin(math.radians(30))
    u = 0.42 * c30 + 0.38 * c30 + 0.245 * c30 - 0.04 * s30
    w = 0.42 * s30 - 0.38 * s30 - 0.245 * s30 - 0.04 * c30
    assert pose.x == pytest.approx(-0.12, abs=1e-12)
    assert pose.y == pytest.approx(u, abs=1e-12)
    assert pose.z == pytest.approx(0.37 + w, abs=1e-12)
    assert pose.pitch == pytest.approx(math.radians(-30.0), abs=1e-12)
    # The whole tree agrees with the chain.
    tree = arm.tree.copy()
    tree.set_positions(arm.mapping(q))
    assert np.allclose(tree.world_transform("tool0"), arm.tool_matrix(q), atol=1e-12)


def test_engineer_ik_round_trips_every_reachable_pose(arm: ArmKinematics) -> None:
    """IK(FK(q)) puts the tool where FK(q) did, for poses all over the joint space."""
    rng = np.random.default_rng(7)
    for _ in range(1500):
        q = rng.uniform(arm.chain.lower, arm.chain.upper)
        target = arm.tool_pose(q)
        solved = arm.solve(target, current=q)
        reached = arm.tool_pose(solved)
        assert np.linalg.norm(reached.position - target.position) < 1e-9
        assert reached.pitch == pytest.approx(target.pitch, abs=1e-9)
        assert arm.chain.within_limits(solved)
        # The nearest solution to where the arm is is the arm's own pose.
        assert np.allclose(solved, q, atol=1e-7)


def test_elbow_up_and_down_are_both_offered_and_differ(arm: ArmKinematics) -> None:
    target = ToolPose(0.55, 0.14, 1.0, math.radians(38.0))
    up = arm.solve(target, elbow=ELBOW_UP)
    down = arm.solve(target, elbow=ELBOW_DOWN)
    assert not np.allclose(up, down)
    for q in (up, down):
        assert np.linalg.norm(arm.tool_pose(q).position - target.position) < 1e-9
    tree = arm.tree.copy()
    heights = []
    for q in (up, down):
        tree.set_positions(arm.mapping(q))
        world = tree.world_transforms()
        shoulder, elbow, wrist = (
            world[link][:3, 3] for link in ("upper_arm", "forearm", "neck_link")
        )
        line = shoulder + (wrist - shoulder) * (
            np.dot(elbow - shoulder, wrist - shoulder) / np.dot(wrist - shoulder, wrist - shoulder)
        )
        heights.append(elbow[2] - line[2])
    assert heights[0] > 0.0 > heights[1]  # up: above the shoulder-wrist line; down: below


def test_unreachable_targets_are_refused_with_the_reason(arm: ArmKinematics) -> None:
    with pytest.raises(ArmError, match=r"out of reach: the wrist point would be \d+ mm from the "
                       r"shoulder axis; the arm reaches 800 mm"):  # fmt: skip
        arm.solve(ToolPose(2.0, 0.0, 0.4, 0.0))
    # Straight behind: the waist stops at 170°, and reaching over the top needs the shoulder
    # past its 120°.
    with pytest.raises(
        ArmError,
        match=r"elbow up: waist would need 180\.0° \(limits -170\.0° to 170\.0°\);.*"
        r"over the top, elbow up: shoulder would need 147\.7° \(limits -10\.0° to 120\.0°\)",
    ):
        arm.solve(ToolPose(-0.9, 0.0, 0.3, 0.0))
    with pytest.raises(ArmError, match="finite"):
        arm.solve(ToolPose(math.nan, 0.0, 0.4, 0.0))


def test_analytic_ik_refuses_a_chain_without_its_structure() -> None:
    model = load_urdf(DATA / "ur5_dh.urdf", meshes=False)
    chain = Chain(model.tree, "base_link", "tool0")
    with pytest.raises(ChainError, match="4 joints"):
        YawPitchArm(chain)
    engineer = Chain(
        load_urdf(meshes=False).tree,
        "base_link",
        "tool0",
        variables=["waist", "shoulder", "elbow", "neck"],
    )
    # A planar arm's IK also refuses what it cannot do (the Engineer, straight up high).
    with pytest.raises(UnreachableError, match="out of reach"):
        YawPitchArm(engineer).solve((0.0, 0.0, 3.0), 0.0)


def _dh_standard(q: Array) -> Array:
    """UR5 forward kinematics straight from the standard DH table."""
    d = [0.089159, 0.0, 0.0, 0.10915, 0.09465, 0.0823]
    a = [0.0, -0.425, -0.39225, 0.0, 0.0, 0.0]
    alpha = [math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0]
    result = np.eye(4)
    for i in range(6):
        ct, st = math.cos(q[i]), math.sin(q[i])
        ca, sa = math.cos(alpha[i]), math.sin(alpha[i])
        result = result @ np.array(
            [
                [ct, -st * ca, st * sa, a[i] * ct],
                [st, ct * ca, -ct * sa, a[i] * st],
                [0.0, sa, ca, d[i]],
                [0.0, 0.0, 0.0, 1.0],
            ]
        )
    return result


def _dh_modified(q: Array) -> Array:
    """Panda forward kinematics straight from the modified (Craig) DH table, plus the flange."""
    a = [0.0, 0.0, 0.0, 0.0825, -0.0825, 0.0, 0.088]
    d = [0.333, 0.0, 0.316, 0.0, 0.384, 0.0, 0.0]
    alpha = [0.0, -math.pi / 2, math.pi / 2, math.pi / 2, -math.pi / 2, math.pi / 2, math.pi / 2]
    result = np.eye(4)
    for i in range(7):
        ct, st = math.cos(q[i]), math.sin(q[i])
        ca, sa = math.cos(alpha[i]), math.sin(alpha[i])
        result = result @ np.array(
            [
                [ct, -st, 0.0, a[i]],
                [st * ca, ct * ca, -sa, -d[i] * sa],
                [st * sa, ct * sa, ca, d[i] * ca],
                [0.0, 0.0, 0.0, 1.0],
            ]
        )
    return result @ transform((0.0, 0.0, 0.107))


@pytest.mark.parametrize(("name", "dh"), [("ur5_dh", _dh_standard), ("panda_dh", _dh_modified)])
def test_other_arms_fk_matches_their_dh_tables(name: str, dh: object) -> None:
    chain = Chain(load_urdf(DATA / f"{name}.urdf", meshes=False).tree, "base_link", "tool0")
    rng = np.random.default_rng(3)
    for _ in range(200):
        q = rng.uniform(np.maximum(chain.lower, -math.pi), np.minimum(chain.upper, math.pi))
        assert np.allclose(chain.forward(q), dh(q), atol=1e-8)  # type: ignore[operator]


@pytest.mark.parametrize("name", ["ur5_dh", "panda_dh"])
def test_numeric_ik_round_trips_other_arms(name: str) -> None:
    """Damped least squares reaches full poses (position and orientation) of 6- and 7-joint
    arms from a start far from the answer."""
    chain = Chain(load_urdf(DATA / f"{name}.urdf", meshes=False).tree, "base_link", "tool0")
    rng = np.random.default_rng(11)
    low, high = np.maximum(chain.lower, -math.pi), np.minimum(chain.upper, math.pi)
    for _ in range(25):
        q = rng.uniform(low, high)
        target = chain.forward(q)
        start = chain.clamp(q + rng.uniform(-0.8, 0.8, chain.dof))
        solution = solve(chain, target, start)
        reached = chain.forward(solution.q)
        assert np.linalg.norm(reached[:3, 3] - target[:3, 3]) < 1e-4
        assert np.allclose(reached[:3, :3], target[:3, :3], atol=1e-3)
        assert chain.within_limits(solution.q)


def test_numeric_ik_says_how_close_it_came() -> None:
    chain = Chain(load_urdf(DATA / "ur5_dh.urdf", meshes=False).tree, "base_link", "tool0")
    with pytest.raises(IkError, match=r"the closest was \d+\.\d mm"):
        solve(chain, transform((2.0, 0.0, 0.5)), restarts=2)


@pytest.mark.parametrize("name", ["ur5_dh", "panda_dh", "engineer"])
def test_jacobian_matches_finite_differences(name: str) -> None:
    path = None if name == "engineer" else DATA / f"{name}.urdf"
    chain = Chain(load_urdf(path, meshes=False).tree, "base_link", "tool0")
    rng = np.random.default_rng(5)
    q = rng.uniform(np.maximum(chain.lower, -1.0), np.minimum(chain.upper, 1.0))
    jac = chain.jacobian(q)
    step = 1e-6
    for i in range(chain.dof):
        dq = np.zeros(chain.dof)
        dq[i] = step
        ahead, behind = chain.forward(q + dq), chain.forward(q - dq)
        assert np.allclose((ahead[:3, 3] - behind[:3, 3]) / (2 * step), jac[:3, i], atol=1e-6)
        # Angular part: the skew part of dR Rᵀ.
        rate = (ahead[:3, :3] - behind[:3, :3]) / (2 * step) @ chain.forward(q)[:3, :3].T
        omega = np.array([rate[2, 1], rate[0, 2], rate[1, 0]])
        assert np.allclose(omega, jac[3:, i], atol=1e-6)


def test_task_jacobian_pitch_row_is_the_pitch_derivative(arm: ArmKinematics) -> None:
    q = np.radians([25.0, 40.0, 70.0, -15.0])
    jac = arm.task_jacobian(q)
    for i in range(4):
        dq = np.zeros(4)
        dq[i] = 1e-6
        ahead, behind = arm.tool_pose(q + dq), arm.tool_pose(q - dq)
        assert (ahead.pitch - behind.pitch) / 2e-6 == pytest.approx(jac[3, i], abs=1e-6)
        assert (ahead.x - behind.x) / 2e-6 == pytest.approx(jac[0, i], abs=1e-6)


def test_chain_mimic_held_joints_and_errors() -> None:
    tree = load_urdf(meshes=False).tree
    # The right jaw mimics the gripper, which is not on its chain: held at the gripper's value.
    jaw = Chain(tree, "gripper_base", "right_jaw")
    assert jaw.joints == ()
    assert jaw.held_joints == ("gripper",)
    closed = jaw.forward([])
    jaw.hold({"gripper": 0.5})
    assert np.allclose(
        jaw.forward([])[:3, :3], closed[:3, :3] @ transform(rpy=(0, 0, -0.5))[:3, :3]
    )
    tool = Chain(tree, "base_link", "tool0", variables=["waist", "shoulder", "elbow", "neck"])
    assert tool.held_joints == ("gripper_roll",)
    q = np.radians([0.0, 10.0, 20.0, 30.0])
    before = tool.forward(q)
    tool.hold({"gripper_roll": math.radians(90.0)})
    after = tool.forward(q)
    # The roll turns tool0 about its own x axis: the position and x axis stay, y and z turn.
    assert np.allclose(before[:3, 3], after[:3, 3])
    assert np.allclose(before[:3, 0], after[:3, 0])
    assert np.allclose(after[:3, 1], before[:3, 2], atol=1e-12)
    with pytest.raises(ChainError, match="not above"):
        Chain(tree, "tool0", "base_link")
    with pytest.raises(ChainError, match="does not move the chain"):
        Chain(tree, "base_link", "tool0", variables=["flippers"])
    with pytest.raises(ChainError, match="expected 4 values"):
        tool.forward([0.0, 0.0])


def test_jog_frames_are_the_tree_frames(arm: ArmKinematics) -> None:
    """base, tool (tool0) and camera (head_cameras, the head's pan as read) orientations."""
    q = np.radians([35.0, 50.0, 80.0, -25.0])
    others = {"head_pan": math.radians(20.0), "gripper_roll": math.radians(10.0)}
    arm.hold(others)
    tree = arm.tree.copy()
    tree.set_positions({**others, **arm.mapping(q)})
    assert np.allclose(arm.frame_rotation("base", q, others), np.eye(3))
    assert np.allclose(arm.frame_rotation("tool", q, others), tree.world_transform("tool0")[:3, :3])
    camera = tree.world_transform("head_cameras")[:3, :3]
    assert np.allclose(arm.frame_rotation("camera", q, others), camera)
    with pytest.raises(ArmError, match="unknown jog frame 'world'"):
        arm.frame_rotation("world", q, others)
    arm.hold({"head_pan": 0.0, "gripper_roll": 0.0})
