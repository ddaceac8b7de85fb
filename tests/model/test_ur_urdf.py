"""The UR's URDF (ocu.profile.ur_urdf): the shipped files are the generator's output, and
their forward kinematics are the UR profile's DH forward kinematics, in ROS's frames."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest
from pytestqt.qtbot import QtBot

from ocu.kinematics.chain import Chain
from ocu.model.urdf import default_urdf_path, load_urdf, profile_urdf_path
from ocu.profile import load_profile
from ocu.profile.ur import UrArmProfile, load_ur_profile, shipped_ur_profiles
from ocu.profile.ur_robot import ur_robot_profile
from ocu.profile.ur_urdf import shipped_urdf_path, ur_urdf, ur_urdf_path
from ocu.sim.ur_arm import forward_kinematics
from ocu.widgets.model3d import Model3DWidget

MODELS = ("ur3e", "ur5e", "ur10e", "ur5")
Matrix = npt.NDArray[np.float64]


def dh_forward(arm: UrArmProfile, q: npt.NDArray[np.float64]) -> Matrix:
    """The flange in the controller's base frame: the product of the standard DH rows (the
    UR simulator's forward kinematics, which the URDF is checked against)."""
    return forward_kinematics(arm, list(q))


def test_the_shipped_profiles_each_have_their_urdf_and_it_is_the_generators() -> None:
    assert set(shipped_ur_profiles()) == set(MODELS)  # not the key map or the pad mapping
    for name in MODELS:
        arm = load_ur_profile(name)
        assert shipped_urdf_path(name).read_text(encoding="utf-8") == ur_urdf(arm), (
            f"{name}: run python -m ocu.profile.ur_urdf"
        )
        assert ur_robot_profile(arm).urdf == shipped_urdf_path(name)


@pytest.mark.parametrize("name", MODELS)
def test_tool0_is_where_the_dh_parameters_put_the_flange(name: str) -> None:
    arm = load_ur_profile(name)
    model = load_urdf(ur_robot_profile(arm).urdf)
    assert model.warnings == ()
    tree = model.tree
    # In the controller's frame (`base`, which base_link_inertia coincides with, checked
    # below; `base` is a leaf) tool0 is the DH flange, position and orientation.
    chain = Chain(tree, "base_link_inertia", "tool0", variables=arm.joint_names)
    assert chain.joints == arm.joint_names
    turn = np.diag([-1.0, -1.0, 1.0, 1.0])  # base_link is `base` turned 180° about z
    link_chain = Chain(tree, "base_link", "tool0", variables=arm.joint_names)
    rng = np.random.default_rng(22)
    for q in [np.zeros(6), *rng.uniform(-math.pi, math.pi, (6, 6))]:
        expected = dh_forward(arm, q)
        pose = chain.forward(q)
        assert np.linalg.norm(pose[:3, 3] - expected[:3, 3]) < 1e-3  # within 1 mm
        assert np.allclose(pose, expected, atol=1e-6)
        assert np.allclose(link_chain.forward(q), turn @ expected, atol=1e-6)
    # The joints carry the profile's limits (none: continuous, as the UR3e's wrist 3).
    for joint in arm.joints:
        urdf_joint = tree.joint(joint.name)
        if joint.min_rad is None or joint.max_rad is None:
            assert (urdf_joint.type, urdf_joint.limits) == ("continuous", None)
        else:
            assert urdf_joint.type == "revolute"
            assert urdf_joint.limits == pytest.approx((joint.min_rad, joint.max_rad))
    # The frames ROS-Industrial names: base, base_link, base_link_inertia, flange, tool0.
    assert {"base", "base_link", "base_link_inertia", "flange", "tool0", "ft_frame"} <= set(
        tree.links
    )
    world = tree.world_transforms()
    assert np.allclose(world["base_link_inertia"], world["base"], atol=1e-9)
    assert np.allclose(world["flange"][:3, 3], world["tool0"][:3, 3], atol=1e-9)


def test_a_ur5e_at_zero_has_tool0_where_ur_publishes_it() -> None:
    """UR's DH article: at zero joints the UR5e's TCP is at (-817.2, -232.9, 62.8) mm in the
    controller's base frame; ROS's base_link has x and y the other way round."""
    model = load_urdf(shipped_urdf_path("ur5e"))
    tree = model.tree.copy()
    tree.set_positions(dict.fromkeys(load_ur_profile("ur5e").joint_names, 0.0))
    in_base_link = tree.world_transform("tool0")[:3, 3]
    assert in_base_link == pytest.approx([0.8172, 0.2329, 0.0628], abs=1e-4)
    in_base = np.linalg.inv(tree.world_transform("base")) @ tree.world_transform("tool0")
    assert in_base[:3, 3] == pytest.approx([-0.8172, -0.2329, 0.0628], abs=1e-4)


def test_a_ur_profile_from_another_file_gets_a_urdf_written_from_its_own_dh(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    text = (shipped_urdf_path("ur5e").with_suffix(".toml")).read_text(encoding="utf-8")
    mine = tmp_path / "my_ur.toml"
    mine.write_text(text.replace('name = "ur5e"', 'name = "my_ur"').replace("0.1625", "0.2"))
    arm = load_ur_profile(mine)
    path = ur_urdf_path(arm)
    assert path.parent == tmp_path / "cache" / "ocu" / "urdf"
    assert path.read_text(encoding="utf-8") == ur_urdf(arm)
    assert ur_urdf_path(arm) == path  # written once
    tree = load_urdf(path).tree
    tool = Chain(tree, "base_link_inertia", "tool0").forward(np.zeros(6))
    assert np.allclose(tool, dh_forward(arm, np.zeros(6)), atol=1e-6)
    assert tool[2, 3] == pytest.approx(0.2 - 0.0997)  # its own d1
    # A URDF beside the profile (a vendor's, with meshes) is used as it is.
    beside = tmp_path / "my_ur.urdf"
    beside.write_text(ur_urdf(arm), encoding="utf-8")
    assert ur_urdf_path(arm) == beside


def test_the_engineer_keeps_its_model() -> None:
    engineer = load_profile()
    assert engineer.urdf is None
    assert profile_urdf_path(engineer) == default_urdf_path()


def test_the_3d_view_draws_the_profiles_robot(qtbot: QtBot) -> None:
    profile = ur_robot_profile(load_ur_profile("ur5e"))
    view = Model3DWidget(profile)
    qtbot.addWidget(view)
    try:
        assert view.model.source == str(shipped_urdf_path("ur5e"))
        assert set(load_ur_profile("ur5e").joint_names) <= view.tracked_joints
    finally:
        view.release()
