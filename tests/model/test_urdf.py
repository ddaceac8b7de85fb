"""URDF loading: the shipped Engineer agrees with the profile; other models drop in; errors."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest
import trimesh

from ocu.model.urdf import (
    COLLISION_ONLY_NOTE,
    RobotModel,
    UrdfError,
    default_urdf_path,
    load_urdf,
    parse_urdf,
)
from ocu.profile import RobotProfile

REPO = Path(__file__).resolve().parents[2]
MODELLED_MOTORS = ("flippers", "waist", "shoulder", "elbow", "neck", "gripper")


def test_engineer_has_the_parts_of_the_robot(engineer: RobotModel) -> None:
    links = set(engineer.tree.links)
    assert {
        "base_link", "left_track", "right_track", "left_flipper", "right_flipper", "turret",
        "upper_arm", "forearm", "neck_link", "head", "head_cameras", "gripper_base",
        "left_jaw", "right_jaw",
    } <= links  # fmt: skip
    assert all(engineer.meshes[name].vertex_count > 0 for name in links - {"tool0"})
    # tool0, the grasp point between the jaws, is a bare frame on the gripper.
    assert engineer.meshes["tool0"].vertex_count == 0
    assert engineer.tree.parent_joint("tool0").parent == "gripper_base"  # type: ignore[union-attr]
    assert engineer.warnings == ()
    assert engineer.tree.root == "base_link"
    assert engineer.tree.joint("left_track_mount").type == "fixed"


def test_engineer_joints_match_the_profile(engineer: RobotModel, profile: RobotProfile) -> None:
    """Joint names are motor names and limits are the profile's, exactly."""
    tree = engineer.tree
    for name in MODELLED_MOTORS:
        assert name in tree.actuated_joints
    for name in tree.actuated_joints:
        motor = profile.motors.get(name)
        assert motor is not None, f"URDF joint {name!r} is not a profile motor"
        assert motor.has_position
        assert tree.joint(name).limits == motor.limits_rad
    for motor in profile.motors.values():
        if motor.track is not None:
            assert motor.name not in tree.joints  # tracks are fixed parts of the chassis


def test_engineer_track_spacing_is_the_profiles(
    engineer: RobotModel, profile: RobotProfile
) -> None:
    world = engineer.tree.world_transforms()
    spacing = world["left_track"][1, 3] - world["right_track"][1, 3]
    assert spacing == pytest.approx(profile.track_width_m)


def test_each_moving_mesh_has_its_origin_on_its_joint(engineer: RobotModel) -> None:
    """Meshes are in their link frame: the joint (the frame origin) is at or near the mesh."""
    for link in engineer.tree.links:
        joint = engineer.tree.parent_joint(link)
        if joint is None or joint.type == "fixed":
            continue
        low, high = engineer.meshes[link].bounds()
        gap = np.maximum(np.maximum(low, 0.0), np.maximum(-high, 0.0))
        assert np.linalg.norm(gap) < 0.02, f"{link}: mesh is {gap} m away from its joint"


def test_engineer_model_files_are_small() -> None:
    folder = default_urdf_path().parent
    total = sum(path.stat().st_size for path in folder.rglob("*") if path.is_file())
    assert total < 512 * 1024


def test_generator_reproduces_the_committed_files(tmp_path: Path) -> None:
    script = REPO / "tools" / "make_engineer_model.py"
    subprocess.run(
        [sys.executable, str(script), "--out", str(tmp_path)],
        check=True,
        capture_output=True,
        timeout=60,
    )
    committed = default_urdf_path().parent
    made = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*") if p.is_file())
    assert made == sorted(p.relative_to(committed) for p in committed.rglob("*") if p.is_file())
    for relative in made:
        fresh, kept = tmp_path / relative, committed / relative
        if relative.suffix == ".stl":
            # Same triangles, whatever order a trimesh release lists them in.
            new, old = _triangle_set(fresh), _triangle_set(kept)
            same = new.shape == old.shape and np.allclose(new, old, atol=1e-6)
            assert same, f"{relative} differs: rerun tools/make_engineer_model.py"
        else:
            assert fresh.read_text() == kept.read_text(), f"{relative} differs"


def _triangle_set(path: Path) -> npt.NDArray[np.float64]:
    """Triangles of a binary STL in a canonical order: corners sorted, then triangles."""
    record = np.dtype([("normal", "<f4", 3), ("vertices", "<f4", (3, 3)), ("attr", "<u2")])
    triangles = np.frombuffer(path.read_bytes()[84:], dtype=record)["vertices"]
    rounded = np.round(triangles.astype(np.float64), 6)
    corners = np.sort(rounded.view("f8,f8,f8").reshape(-1, 3), axis=1)
    ordered = np.sort(corners.view("f8").reshape(-1, 9).view(",".join(["f8"] * 9)), axis=0)
    return ordered.view("f8").reshape(-1, 9)


def _urdf(body: str) -> str:
    return f'<?xml version="1.0"?>\n<robot name="t">\n{body}\n</robot>\n'


def _box_link(name: str) -> str:
    return (
        f'<link name="{name}"><visual><geometry><box size="0.1 0.1 0.1"/></geometry>'
        "</visual></link>"
    )


def _joint(name: str, parent: str, child: str, kind: str = "continuous", extra: str = "") -> str:
    return (
        f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
        f'<axis xyz="0 0 1"/>{extra}</joint>'
    )


def test_primitives_materials_and_origins(tmp_path: Path) -> None:
    text = _urdf(
        '<material name="red"><color rgba="1 0 0 1"/></material>'
        '<link name="a"><visual><origin xyz="0 0 1"/><geometry><box size="2 2 2"/></geometry>'
        '<material name="red"/></visual></link>'
        '<link name="b"><visual><geometry><cylinder radius="0.5" length="1"/></geometry>'
        '<material name="x"><color rgba="0 0 1 0.5"/></material></visual>'
        '<visual><geometry><sphere radius="0.25"/></geometry></visual></link>'
        + _joint("j", "a", "b", "revolute", '<limit lower="-1" upper="2"/>')
    )
    model = parse_urdf(text, tmp_path)
    low, high = model.meshes["a"].bounds()
    assert np.allclose(low, [-1, -1, 0])
    assert np.allclose(high, [1, 1, 2])
    assert (model.meshes["a"].colors == [255, 0, 0, 255]).all()
    b_colors = {tuple(c) for c in model.meshes["b"].colors.tolist()}
    assert (0, 0, 255, 128) in b_colors
    assert len(b_colors) == 2
    assert model.tree.joint("j").limits == (-1.0, 2.0)


def test_other_mesh_formats_drop_in(tmp_path: Path) -> None:
    """OBJ, PLY and GLB meshes load, by relative and package:// paths; own colours are kept."""
    package = tmp_path / "my_robot"
    (package / "meshes").mkdir(parents=True)
    (package / "urdf").mkdir()
    cube = trimesh.creation.box(extents=(0.2, 0.2, 0.2))
    cube.visual.face_colors = [10, 200, 30, 255]
    cube.export(package / "meshes" / "cube.ply")
    ball: trimesh.Trimesh = trimesh.creation.icosphere(subdivisions=1, radius=0.1)
    ball.export(package / "meshes" / "ball.obj")
    tinted = trimesh.creation.box(extents=(0.2, 0.2, 0.2))
    tinted.visual.vertex_colors = [200, 20, 20, 255]
    tinted.export(package / "meshes" / "cube.glb")
    urdf = package / "urdf" / "robot.urdf"
    urdf.write_text(
        _urdf(
            '<link name="base"><visual><geometry>'
            '<mesh filename="package://my_robot/meshes/cube.ply"/></geometry></visual></link>'
            '<link name="arm"><visual><geometry>'
            '<mesh filename="../meshes/ball.obj" scale="2 2 2"/></geometry></visual></link>'
            '<link name="tool"><visual><geometry>'
            '<mesh filename="package://my_robot/meshes/cube.glb"/></geometry></visual></link>'
            + _joint("j1", "base", "arm")
            + _joint("j2", "arm", "tool", "fixed")
        )
    )
    model = load_urdf(urdf)
    assert model.meshes["base"].triangle_count == 12
    assert (model.meshes["base"].colors[:, :3] == [10, 200, 30]).all()
    assert model.meshes["tool"].triangle_count == 12
    assert (model.meshes["tool"].colors[:, :3] == [200, 20, 20]).all()
    _low, high = model.meshes["arm"].bounds()
    assert high[0] == pytest.approx(0.2, abs=1e-6)  # scaled by 2
    assert model.tree.actuated_joints == ("j1",)


def test_a_missing_or_unreadable_mesh_leaves_the_rest_of_the_robot(tmp_path: Path) -> None:
    """One bad mesh is skipped with a warning naming the file and where it was looked for."""
    (tmp_path / "bad.stl").write_bytes(b"not a mesh at all")
    urdf = tmp_path / "r.urdf"
    urdf.write_text(
        _urdf(
            '<link name="base"><visual><geometry><mesh filename="meshes/gone.stl"/>'
            "</geometry></visual></link>"
            '<link name="arm"><visual><geometry><mesh filename="bad.stl"/></geometry></visual>'
            '<visual><geometry><box size="0.1 0.1 0.1"/></geometry></visual></link>'
            + _joint("j", "base", "arm")
        )
    )
    model = load_urdf(urdf)
    assert model.meshes["base"].vertex_count == 0
    assert model.meshes["arm"].triangle_count == 12  # the box of the second visual
    assert len(model.warnings) == 2
    assert re.search(
        r"link 'base' visual 0: mesh file not found: meshes/gone.stl \(looked in: .*gone.stl\)"
        r"; the rest of the robot is drawn",
        model.warnings[0],
    )
    assert re.search(r"link 'arm' visual 0: (cannot read mesh|mesh ).*bad", model.warnings[1])


def test_a_mimic_of_a_missing_joint_moves_on_its_own(tmp_path: Path) -> None:
    text = _urdf(
        _box_link("a") + _box_link("b")
        + _joint("j", "a", "b", extra='<mimic joint="nope"/>')
    )  # fmt: skip
    model = parse_urdf(text, tmp_path)
    assert model.tree.actuated_joints == ("j",)
    assert model.warnings == (
        "joint 'j' mimics 'nope', which is not a moving joint of this model: it moves on its own",
    )


def test_a_robot_without_a_moving_joint_loads_and_renders(tmp_path: Path) -> None:
    text = _urdf(_box_link("a") + _box_link("b") + _joint("j", "a", "b", "fixed"))
    model = parse_urdf(text, tmp_path)
    assert model.tree.actuated_joints == ()
    assert set(model.tree.world_transforms()) == {"a", "b"}


def _collada_document(mesh: trimesh.Trimesh) -> str:
    """A minimal Collada 1.4.1 file of one triangle mesh, written as text: exporting through
    trimesh would go through pycollada's writer, which sets ndarray.shape (deprecated in numpy
    2.5); what is tested here is our reading of a file, through pycollada's reader."""
    positions = " ".join(f"{v:.6f}" for v in np.asarray(mesh.vertices).ravel())
    indices = " ".join(str(int(i)) for i in np.asarray(mesh.faces).ravel())
    count, points = len(mesh.faces), len(mesh.vertices)
    return f"""<?xml version="1.0" encoding="utf-8"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset><unit name="meter" meter="1"/><up_axis>Z_UP</up_axis></asset>
  <library_geometries>
    <geometry id="part" name="part"><mesh>
      <source id="part-positions">
        <float_array id="part-positions-array" count="{points * 3}">{positions}</float_array>
        <technique_common><accessor source="#part-positions-array" count="{points}" stride="3">
          <param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/>
        </accessor></technique_common>
      </source>
      <vertices id="part-vertices"><input semantic="POSITION" source="#part-positions"/></vertices>
      <triangles count="{count}"><input semantic="VERTEX" source="#part-vertices" offset="0"/>
        <p>{indices}</p></triangles>
    </mesh></geometry>
  </library_geometries>
  <library_visual_scenes><visual_scene id="scene">
    <node id="part-node"><instance_geometry url="#part"/></node>
  </visual_scene></library_visual_scenes>
  <scene><instance_visual_scene url="#scene"/></scene>
</COLLADA>
"""


def test_collada_meshes_load_through_pycollada(tmp_path: Path) -> None:
    box = trimesh.creation.box(extents=(0.3, 0.2, 0.1))
    (tmp_path / "part.dae").write_text(_collada_document(box))
    text = _urdf(
        '<link name="a"><visual><geometry><mesh filename="part.dae"/></geometry></visual></link>'
    )
    model = parse_urdf(text, tmp_path)
    assert model.warnings == ()
    low, high = model.meshes["a"].bounds()
    assert np.allclose(high - low, [0.3, 0.2, 0.1], atol=1e-6)


def test_package_with_an_empty_name_and_materials_reused_by_name(tmp_path: Path) -> None:
    (tmp_path / "meshes").mkdir()
    trimesh.creation.box(extents=(0.1, 0.1, 0.1)).export(tmp_path / "meshes" / "cube.stl")
    absolute = tmp_path / "meshes" / "cube.stl"
    text = _urdf(
        '<link name="a"><visual><geometry><mesh filename="package:///meshes/cube.stl"/>'
        '</geometry><material name="signal"><color rgba="1 0.5 0 1"/></material></visual></link>'
        f'<link name="b"><visual><geometry><mesh filename="package://{absolute}"/>'
        '</geometry><material name="signal"/></visual></link>' + _joint("j", "a", "b")
    )
    model = parse_urdf(text, tmp_path)
    assert model.warnings == ()
    assert model.meshes["a"].triangle_count == 12
    assert model.meshes["b"].triangle_count == 12
    # Defined in link a's visual, used by name in link b's: b is orange, not the default grey.
    assert (model.meshes["b"].colors == [255, 128, 0, 255]).all()


def test_collision_only_robot_is_drawn_from_its_collision_geometry(tmp_path: Path) -> None:
    text = _urdf(
        '<link name="a"><collision><origin xyz="0 0 0.5"/><geometry><box size="1 1 1"/>'
        "</geometry></collision></link>"
        '<link name="b"><collision><geometry><cylinder radius="0.1" length="0.4"/></geometry>'
        "</collision></link>" + _joint("j", "a", "b")
    )
    model = parse_urdf(text, tmp_path)
    assert model.drawn_from_collision
    assert COLLISION_ONLY_NOTE in model.warnings
    assert model.meshes["a"].triangle_count == 12
    assert model.meshes["b"].vertex_count > 0
    low, _high = model.meshes["a"].bounds()
    assert np.allclose(low, [-0.5, -0.5, 0.0])
    assert model.collisions["a"][0].kind == "box"
    assert model.collisions["b"][0].size == (0.1, 0.1, 0.4)


def test_xacro_leftovers_get_a_hint(tmp_path: Path) -> None:
    text = _urdf(
        '<link name="a"><visual><geometry><mesh filename="$(find my_robot)/meshes/a.stl"/>'
        "</geometry></visual></link>"
    )
    model = parse_urdf(text, tmp_path)
    assert any("unprocessed xacro" in warning for warning in model.warnings)
    with pytest.raises(UrdfError, match=r"origin rpy.*unprocessed xacro file: expand it first"):
        parse_urdf(
            _urdf(_box_link("a") + _box_link("b")
                  + _joint("j", "a", "b", extra='<origin rpy="0 0 ${pi/2}"/>')),
            tmp_path,
        )  # fmt: skip
    source = tmp_path / "robot.urdf.xacro"
    source.write_text('<robot xmlns:xacro="http://www.ros.org/wiki/xacro" name="r">'
                      '<xacro:macro name="m"/></robot>')  # fmt: skip
    with pytest.raises(UrdfError, match=r"xacro robot\.urdf\.xacro > robot\.urdf"):
        load_urdf(source)


def test_cycle_is_reported_with_its_joints(tmp_path: Path) -> None:
    text = _urdf(_box_link("a") + _box_link("b") + _joint("ab", "a", "b") + _joint("ba", "b", "a"))
    with pytest.raises(UrdfError, match=r"no root link; joints form a cycle: .*ab.*ba"):
        parse_urdf(text, tmp_path)
    text = _urdf(
        _box_link("r") + _box_link("a") + _box_link("b")
        + _joint("ra", "r", "a") + _joint("ab", "a", "b") + _joint("ba", "b", "a")
    )  # fmt: skip
    with pytest.raises(UrdfError, match=r"link 'a' has two parent joints"):
        parse_urdf(text, tmp_path)


def test_unknown_and_unsupported_joint_types(tmp_path: Path) -> None:
    text = _urdf(_box_link("a") + _box_link("b") + _joint("j", "a", "b", "hinge"))
    with pytest.raises(
        UrdfError,
        match=r"joint 'j': unknown joint type 'hinge' \(expected one of fixed, revolute, "
        r"continuous, prismatic, floating, planar, spherical\)",
    ):
        parse_urdf(text, tmp_path)
    for kind in ("floating", "planar", "spherical"):
        text = _urdf(_box_link("a") + _box_link("b") + _joint("j", "a", "b", kind))
        model = parse_urdf(text, tmp_path)
        assert model.tree.joint("j").type == "fixed"
        assert re.search(rf"line 3: joint 'j': a {kind} joint .* drawn fixed", model.warnings[0])


def test_other_structural_errors(tmp_path: Path) -> None:
    cases = {
        "not valid XML": "<robot><link name='a'></robot>",
        r"root element is <model>": "<model/>",
        r"no <link> elements": _urdf(""),
        r"2 links have no parent joint \(a, b\)": _urdf(_box_link("a") + _box_link("b")),
        r"joint 'j': child link 'z' is not defined": _urdf(
            _box_link("a") + _joint("j", "a", "z")
        ),
        r"joint 'j' origin xyz: '1 2' is not 3": _urdf(
            _box_link("a") + _box_link("b")
            + _joint("j", "a", "b", extra='<origin xyz="1 2"/>')
        ),
        r"joint 'j' limit lower: '-1.5.7' is not 1 numbers": _urdf(
            _box_link("a") + _box_link("b")
            + _joint("j", "a", "b", "revolute", '<limit lower="-1.5.7" upper="1"/>')
        ),
    }  # fmt: skip
    for message, text in cases.items():
        with pytest.raises(UrdfError, match=message):
            parse_urdf(text, tmp_path, source="test.urdf")


def test_missing_urdf_file(tmp_path: Path) -> None:
    with pytest.raises(UrdfError, match=r"cannot read URDF .*nothing.urdf"):
        load_urdf(tmp_path / "nothing.urdf")
