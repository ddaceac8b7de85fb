"""Kinematic tree: hand-computed transforms, no drift over a million updates, clear errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ocu.model.tree import Joint, KinematicTree, Mimic, TreeError, axis_rotation, transform
from ocu.model.urdf import RobotModel


def _chain() -> KinematicTree:
    """base -a(z)-> l1 -b(y)-> l2 -c(prismatic x)-> l3; l1 -fixed(yaw 90)-> l1f; l1 -m-> l4."""
    return KinematicTree(
        "base",
        ["base", "l1", "l2", "l3", "l1f", "l4"],
        [
            Joint("a", "revolute", "base", "l1", transform((1, 0, 0)), (0, 0, 1), (-4, 4)),
            Joint("b", "continuous", "l1", "l2", transform((0, 0, 2)), (0, 1, 0)),
            Joint("c", "prismatic", "l2", "l3", transform((0.5, 0, 0)), (1, 0, 0), (0, 1)),
            Joint("f", "fixed", "l1", "l1f", transform(rpy=(0, 0, math.pi / 2))),
            Joint("m", "revolute", "l1", "l4", transform((0, 1, 0)), (0, 0, 2), (-9, 9),
                  mimic=Mimic("a", multiplier=2.0, offset=0.1)),
        ],
    )  # fmt: skip


def test_zero_pose_is_the_product_of_the_origins() -> None:
    world = _chain().world_transforms()
    assert np.allclose(world["base"], np.eye(4))
    assert np.allclose(world["l2"][:3, 3], [1, 0, 2])
    assert np.allclose(world["l3"][:3, 3], [1.5, 0, 2])
    assert np.allclose(world["l4"][:3, 3], [1, 1, 0])


def test_transforms_match_hand_computation() -> None:
    tree = _chain()
    tree.set_positions({"a": math.pi / 2, "b": math.pi / 2, "c": 0.3})
    world = tree.world_transforms()
    # l1 = Trans(1,0,0) Rz(90)
    assert np.allclose(world["l1"], [[0, -1, 0, 1], [1, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
    # l2 = l1 Trans(0,0,2) Ry(90): Rz(90) Ry(90) = [[0,-1,0],[0,0,1],[-1,0,0]]
    assert np.allclose(world["l2"], [[0, -1, 0, 1], [0, 0, 1, 0], [-1, 0, 0, 2], [0, 0, 0, 1]])
    # l3 = l2 Trans(0.5 + 0.3, 0, 0): its x axis points down in the world
    l3 = np.array([[0, -1, 0, 1], [0, 0, 1, 0], [-1, 0, 0, 1.2], [0, 0, 0, 1]])
    assert np.allclose(world["l3"], l3)
    # l1f = l1 Rz(90) = Trans(1,0,0) Rz(180)
    assert np.allclose(world["l1f"], [[-1, 0, 0, 1], [0, -1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
    # l4 mimics a: angle 2 * 90 deg + 0.1 rad about z, at l1 + Rz(90) (0,1,0) = (0,0,0)
    angle = math.pi / 2 + math.pi + 0.1
    c, s = math.cos(angle), math.sin(angle)
    l4 = np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
    assert np.allclose(world["l4"], l4)


def test_rpy_is_fixed_axis_roll_then_pitch_then_yaw() -> None:
    roll, pitch, yaw = 0.3, -0.7, 1.1
    expected = (
        axis_rotation((0, 0, 1), yaw) @ axis_rotation((0, 1, 0), pitch)
        @ axis_rotation((1, 0, 0), roll)
    )  # fmt: skip
    expected[:3, 3] = (1, 2, 3)
    assert np.allclose(transform((1, 2, 3), (roll, pitch, yaw)), expected)


def test_axis_is_normalised() -> None:
    tree = KinematicTree(
        "a", ["a", "b"], [Joint("j", "continuous", "a", "b", np.eye(4), (0, 0, 5))]
    )
    tree.set_position("j", math.pi / 2)
    assert np.allclose(tree.world_transform("b"), axis_rotation((0, 0, 1), math.pi / 2))


def test_links_are_ordered_parents_first_and_joints_listed() -> None:
    tree = _chain()
    order = tree.links
    assert order[0] == "base"
    for link in order[1:]:
        joint = tree.parent_joint(link)
        assert joint is not None
        assert order.index(joint.parent) < order.index(link)
    assert set(tree.actuated_joints) == {"a", "b", "c"}
    assert set(tree.links_moved_by("a")) == {"l1", "l4"}
    assert set(tree.subtree("l1")) == {"l1", "l2", "l3", "l1f", "l4"}


def test_copy_has_its_own_positions() -> None:
    tree = _chain()
    clone = tree.copy()
    clone.set_position("a", 1.0)
    assert tree.position("a") == 0.0
    assert not np.allclose(tree.world_transform("l1"), clone.world_transform("l1"))


def test_reading_twice_does_not_recompute() -> None:
    tree = _chain()
    tree.world_transforms()
    count = tree.recompute_count
    tree.world_transforms()
    tree.world_transform("l3")
    assert tree.recompute_count == count
    tree.set_position("b", 0.2)
    tree.world_transforms()
    assert tree.recompute_count == count + 1


def test_a_million_random_updates_end_where_a_fresh_computation_does(
    engineer: RobotModel,
) -> None:
    """Every update goes through set_position; every 100th is read (a full recompute).

    10,000 recomputations from the root happen along the way, each compared with a fresh
    tree set to the same joint values, and the end state is compared once more.
    """
    pristine = engineer.tree
    tree = pristine.copy()
    names = tree.actuated_joints
    limits = np.array([tree.joint(n).limits or (-math.pi, math.pi) for n in names])
    rng = np.random.default_rng(20240601)
    count = 1_000_000
    which = rng.integers(0, len(names), count)
    values = rng.uniform(limits[which, 0], limits[which, 1])
    set_position = tree.set_position
    worst = 0.0
    for step, (index, value) in enumerate(zip(which.tolist(), values.tolist(), strict=True)):
        set_position(names[index], value)
        if step % 100 == 99:
            current = tree.world_array()
            if step % 10_000 == 9_999:
                fresh = pristine.copy()
                fresh.set_positions(tree.positions())
                worst = max(worst, float(np.abs(current - fresh.world_array()).max()))
    fresh = KinematicTree(pristine.root, pristine.links, pristine.joints.values())
    fresh.set_positions(tree.positions())
    worst = max(worst, float(np.abs(tree.world_array() - fresh.world_array()).max()))
    assert tree.recompute_count >= count // 100
    assert worst <= 1e-9


def test_accumulating_rotations_would_drift() -> None:
    """Why transforms are never accumulated: the paper's way drifts measurably."""
    rng = np.random.default_rng(7)
    deltas = rng.uniform(-0.2, 0.2, 100_000)
    accumulated = np.eye(3, dtype=np.float32)
    for delta in deltas.tolist():
        c, s = math.cos(delta), math.sin(delta)
        step = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]], dtype=np.float32)
        accumulated = step @ accumulated
    exact = axis_rotation((0, 0, 1), float(deltas.sum()))[:3, :3]
    assert np.abs(accumulated - exact).max() > 1e-7  # versus 1e-9 kept above


def test_setting_unknown_mimic_or_fixed_joints_is_refused() -> None:
    tree = _chain()
    with pytest.raises(TreeError, match=r"unknown joint 'nope'; this model has: a, b, c"):
        tree.set_position("nope", 1.0)
    with pytest.raises(TreeError, match=r"joint 'm' mimics 'a': set that one"):
        tree.set_position("m", 1.0)
    with pytest.raises(TreeError, match=r"joint 'f' is fixed"):
        tree.set_position("f", 1.0)


def _joint(name: str, parent: str, child: str, kind: str = "continuous") -> Joint:
    return Joint(name, kind, parent, child, np.eye(4), (0, 0, 1))


def test_structure_errors_are_clear() -> None:
    with pytest.raises(TreeError, match=r"joints form a cycle: (b -> c|c -> b) -> (b|c)"):
        KinematicTree("a", ["a", "b", "c"], [_joint("b", "c", "b"), _joint("c", "b", "c")])
    with pytest.raises(TreeError, match=r"link 'b' has two parent joints \('j1' and 'j2'\)"):
        KinematicTree("a", ["a", "b"], [_joint("j1", "a", "b"), _joint("j2", "a", "b")])
    with pytest.raises(TreeError, match=r"links not connected to the root 'a': c"):
        KinematicTree("a", ["a", "b", "c"], [_joint("j", "a", "b")])
    with pytest.raises(TreeError, match=r"joint 'j': child link 'x' is not defined"):
        KinematicTree("a", ["a"], [_joint("j", "a", "x")])
    with pytest.raises(TreeError, match=r"two links are named 'a'"):
        KinematicTree("a", ["a", "a"], [])
    with pytest.raises(TreeError, match=r"unknown joint type 'twisty'"):
        _joint("j", "a", "b", "twisty")
    with pytest.raises(TreeError, match=r"mimics 'ghost', which is not a moving joint"):
        KinematicTree(
            "a",
            ["a", "b"],
            [Joint("j", "revolute", "a", "b", np.eye(4), (0, 0, 1), (0, 1), Mimic("ghost"))],
        )
