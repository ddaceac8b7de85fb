"""The corpus of small URDFs in tests/model/data/corpus: one file for each way a real robot
description trips a strict reader (issue 25), loaded as other tools load them."""

from __future__ import annotations

import io
import math
import re
import shutil
from collections.abc import Callable
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from ocu.model.check import check_urdf, find_urdfs
from ocu.model.check import main as urdf_check_main
from ocu.model.urdf import COLLISION_FALLBACK_NOTE, UrdfError, load_urdf, parse_urdf
from ocu.render.screenshot import main as screenshot_main
from tests.model.collada_files import collada_box

CORPUS = Path(__file__).parent / "data" / "corpus"

# file: (status, a warning or error it must show, with its line where the file gives one)
EXPECTED = {
    "blank_lines_before_xml.urdf": ("warned", r"line 3: the <\?xml .* not at the start"),
    "capsules_only.urdf": ("warned", r"line 10: joint 'hip': a spherical joint"),
    "collada/collada.urdf": ("warned", r"image 'foot_png'.*drawn without the texture"),
    "commas_in_xyz.urdf": ("warned", r"line 13: joint 'j' origin xyz='0.07, 0, -0.69': commas"),
    "cycle.urdf": ("failed", r"joints form a cycle: ab -> ba -> ab"),
    "data_root/robots/diff_ring.urdf": ("warned", r"line 5: .*meshes/ring.obj is not next to"),
    "deep_package/checkout/robots/a/b/c/deep.urdf": ("loaded", None),
    "limit_trailing_dot.urdf": ("warned", r"line 13: .*'-1.57.' read as -1.57"),
    "mesh_scale_four_numbers.urdf": ("warned", r"line 8: .*scale='2 2 2 2': 4 numbers"),
    "not_xml.urdf": ("failed", r"not valid XML: no element found: line 5"),
    "nul_after_robot.urdf": ("warned", r"line 16: NUL bytes after the XML, ignored"),
    "only_degenerate_geometry.urdf": ("empty", r"line 5: .*degenerate <sphere> \(radius='0.0'\)"),
    "plane_collision.urdf": ("warned", r"line 7: .*<plane> .* is not drawn"),
    "prismatic_lower_above_upper.urdf": ("warned", r"line 13: .*lower=0.5 is above upper=-0.5"),
    "rpy_four_numbers.urdf": ("warned", r"line 13: .*rpy='0 0 1.5708 0': 4 numbers"),
    "spherical_joint.urdf": ("warned", r"line 10: joint 'j': a spherical joint"),
    "xacro_leftover.urdf": ("warned", r"xacro left in the file: line 8: \$\(find my_robot\)"),
    "xacro_namespace_and_comment.urdf": ("loaded", None),
    "zero_radius_sphere.urdf": ("warned", r"line 9: .*visual 1: degenerate <sphere>"),
}


def test_the_corpus_holds_exactly_the_expected_files() -> None:
    found = {str(p.relative_to(CORPUS)) for p in find_urdfs([CORPUS])}
    assert found == set(EXPECTED)


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_each_corpus_file_loads_warns_or_fails_as_expected(name: str) -> None:
    status, pattern = EXPECTED[name]
    result = check_urdf(CORPUS / name)
    assert result.status == status, (result.error, result.model and result.model.warnings)
    if status == "failed":
        assert result.error is not None
        assert re.search(pattern or "", result.error)
        return
    assert result.model is not None
    messages = result.model.warnings
    if pattern is None:
        assert messages == ()
    else:
        assert any(re.search(pattern, m) for m in messages), messages
    for mesh in result.model.meshes.values():
        assert np.isfinite(mesh.positions).all()


def test_what_is_read_means_what_other_tools_read() -> None:
    commas = load_urdf(CORPUS / "commas_in_xyz.urdf")
    assert np.allclose(commas.tree.joint("j").origin[:3, 3], [0.07, 0.0, -0.69])
    rpy = load_urdf(CORPUS / "rpy_four_numbers.urdf")
    yaw = math.atan2(rpy.tree.joint("j").origin[1, 0], rpy.tree.joint("j").origin[0, 0])
    assert yaw == pytest.approx(1.5708)
    scaled = load_urdf(CORPUS / "mesh_scale_four_numbers.urdf")
    low, high = scaled.meshes["arm"].bounds()
    assert np.allclose(high - low, [0.2, 0.2, 0.2], atol=1e-6)
    assert load_urdf(CORPUS / "prismatic_lower_above_upper.urdf").tree.joint("j").limits is None
    assert load_urdf(CORPUS / "limit_trailing_dot.urdf").tree.joint("j").limits == (-1.57, 1.57)
    spherical = load_urdf(CORPUS / "spherical_joint.urdf")
    assert spherical.tree.joint("j").type == "fixed"
    for name in ("blank_lines_before_xml.urdf", "nul_after_robot.urdf"):
        assert load_urdf(CORPUS / name).triangle_count == 24


def test_capsules_are_drawn_and_kept_for_the_collision_check() -> None:
    model = load_urdf(CORPUS / "capsules_only.urdf")
    assert model.drawn_from_collision
    shape = model.collisions["thigh"][0]
    assert (shape.kind, shape.size) == ("cylinder", (0.05, 0.05, 0.4))
    low, high = model.meshes["thigh"].bounds()  # capsule: length plus two radii, along z
    assert np.allclose(high - low, [0.1, 0.1, 0.5], atol=1e-3)
    assert high[2] == pytest.approx(-0.25 + 0.25, abs=1e-3)


def test_unreadable_numbers_are_still_refused(tmp_path: Path) -> None:
    text = (CORPUS / "commas_in_xyz.urdf").read_text()
    for bad in ("0.07, 0", "0.07 zero 1", "1 2 nan"):
        with pytest.raises(UrdfError, match=r"line 13: joint 'j' origin xyz: .* is not 3"):
            parse_urdf(text.replace("0.07, 0, -0.69", bad), tmp_path)


def test_xacro_is_hinted_only_for_what_xacro_left(tmp_path: Path) -> None:
    """Declaring the namespace or naming xacro in a comment is not a leftover."""
    clean = load_urdf(CORPUS / "xacro_namespace_and_comment.urdf")
    assert not any("xacro" in warning for warning in clean.warnings)
    element = (
        (CORPUS / "spherical_joint.urdf")
        .read_text()
        .replace('<link name="arm">', '<link name="arm"><xacro:property name="x" value="1"/>')
    )
    model = parse_urdf(element.replace("<robot ", '<robot xmlns:xacro="x" '), tmp_path)
    assert any(re.search(r"line 7: <xacro:property>.*expand it first", w) for w in model.warnings)


def _package(root: Path, name: str, folder: str | None = None) -> Path:
    package = root / (folder or name)
    (package / "meshes").mkdir(parents=True)
    (package / "package.xml").write_text(f"<package><name>{name}</name></package>")
    shutil.copy(CORPUS / "meshes" / "cube.obj", package / "meshes" / "part.obj")
    return package


def _package_urdf(folder: Path, package: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "robot.urdf"
    path.write_text(
        '<robot name="r"><link name="base"><visual><geometry>'
        f'<mesh filename="package://{package}/meshes/part.obj"/></geometry></visual></link>'
        "</robot>"
    )
    return path


def test_package_roots_far_above_the_urdf_are_found() -> None:
    """talos: the package's root is more than three folders above its URDF."""
    model = load_urdf(CORPUS / "deep_package/checkout/robots/a/b/c/deep.urdf")
    assert model.triangle_count == 12
    assert model.warnings == ()


def test_packages_elsewhere_are_found_through_the_named_roots(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    for variable in ("OCU_PACKAGE_PATH", "ROS_PACKAGE_PATH", "AMENT_PREFIX_PATH"):
        monkeypatch.delenv(variable, raising=False)
    urdf = _package_urdf(tmp_path / "robots", "far_robot")
    missing = load_urdf(urdf)
    assert missing.triangle_count == 0
    assert "--package-path or OCU_PACKAGE_PATH" in missing.warnings[0]
    # --package-path: a workspace crawled for a package.xml of that name
    _package(tmp_path / "ws" / "src" / "group", "far_robot", folder="far_robot_checkout")
    assert load_urdf(urdf, package_paths=[tmp_path / "ws"]).triangle_count == 12
    # the same through the environment
    monkeypatch.setenv("OCU_PACKAGE_PATH", str(tmp_path / "ws"))
    assert load_urdf(urdf).triangle_count == 12
    monkeypatch.delenv("OCU_PACKAGE_PATH")
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "ws" / "src"))
    assert load_urdf(urdf).triangle_count == 12
    monkeypatch.delenv("ROS_PACKAGE_PATH")
    # ament: <prefix>/share/<package>
    _package(tmp_path / "install" / "share", "far_robot")
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(tmp_path / "install"))
    assert load_urdf(urdf).triangle_count == 12


def test_collada_up_axis_is_ignored_and_its_unit_applied_as_rviz_does(tmp_path: Path) -> None:
    """RViz drops assimp's root transform (the up-axis rotation) and scales by <unit>."""
    model = load_urdf(CORPUS / "collada" / "collada.urdf")
    for link, x in (("base", 0.0), ("y_up", 0.3), ("mm", 0.6), ("foot", 0.9)):
        low, high = model.meshes[link].bounds()
        assert np.allclose(low, [x - 0.05, -0.05, 0.0], atol=1e-6), link
        assert np.allclose(high, [x + 0.05, 0.05, 0.3], atol=1e-6), link
    (tmp_path / "no_axis.dae").write_text(collada_box(up_axis=None))  # Collada's default: Y_UP
    text = '<robot name="r"><link name="a"><visual><geometry><mesh filename="no_axis.dae"/>'
    model = parse_urdf(text + "</geometry></visual></link></robot>", tmp_path)
    assert np.allclose(model.meshes["a"].bounds()[1], [0.05, 0.05, 0.3], atol=1e-6)


def test_a_broken_texture_leaves_the_geometry_and_says_so(tmp_path: Path) -> None:
    (tmp_path / "foot.dae").write_text(collada_box(broken_texture=True))
    text = '<robot name="r"><link name="a"><visual><geometry><mesh filename="foot.dae"/>'
    model = parse_urdf(text + "</geometry></visual></link></robot>", tmp_path)
    assert model.triangle_count == 12
    assert len(model.warnings) == 1
    assert "image 'foot_png', which the file does not hold" in model.warnings[0]
    assert "drawn without the texture" in model.warnings[0]


def test_geometry_pycollada_cannot_read_is_not_called_empty(tmp_path: Path) -> None:
    broken = collada_box().replace('target="#material"', 'target="#nowhere"')
    (tmp_path / "part.dae").write_text(broken)
    text = '<robot name="r"><link name="a"><visual><geometry><mesh filename="part.dae"/>'
    model = parse_urdf(text + "</geometry></visual></link></robot>", tmp_path)
    assert "declares 12 triangles, but pycollada could read none" in model.warnings[0]


def test_collision_geometry_is_drawn_when_no_visual_can_be(tmp_path: Path) -> None:
    text = (
        '<robot name="r"><link name="a"><visual><geometry><mesh filename="gone.stl"/>'
        '</geometry></visual><collision><geometry><box size="1 1 1"/></geometry></collision>'
        "</link></robot>"
    )
    model = parse_urdf(text, tmp_path)
    assert model.drawn_from_collision
    assert model.triangle_count == 12
    assert COLLISION_FALLBACK_NOTE in model.warnings


def _run(main: Callable[[list[str]], int], argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        status = main(argv)
    return status, out.getvalue(), err.getvalue()


def test_a_screenshot_of_nothing_is_an_error(tmp_path: Path) -> None:
    out = tmp_path / "empty.png"
    status, _, err = _run(
        screenshot_main,
        [str(out), "--urdf", str(CORPUS / "only_degenerate_geometry.urdf"), "--size", "64x48"],
    )
    assert status == 1
    assert "nothing to draw: the model holds no triangles" in err
    assert "degenerate <sphere>" in err  # the note that says why
    assert not out.exists()


def test_a_zero_sphere_is_dropped_and_the_rest_drawn(tmp_path: Path) -> None:
    """laikago's toes: the screenshot frames the robot and draws it."""
    out = tmp_path / "robot.png"
    urdf = CORPUS / "zero_radius_sphere.urdf"
    status, _, err = _run(screenshot_main, [str(out), "--urdf", str(urdf), "--size", "160x120"])
    assert status == 0, err
    pixels = np.asarray(Image.open(out).convert("RGB"), dtype=np.int16)
    background = pixels[0, 0]
    model_pixels = (np.abs(pixels - background).sum(axis=2) > 60).sum()
    assert model_pixels > 0.05 * 160 * 120  # the two boxes fill a good part of the frame


def test_screenshot_takes_package_paths(tmp_path: Path) -> None:
    urdf = _package_urdf(tmp_path / "robots", "shot_robot")
    _package(tmp_path / "elsewhere", "shot_robot")
    out = tmp_path / "robot.png"
    status, _, err = _run(screenshot_main, [str(out), "--urdf", str(urdf), "--size", "64x48"])
    assert status == 1
    assert "nothing to draw" in err
    argv = [str(out), "--urdf", str(urdf), "--size", "64x48", "--package-path"]
    status, _, err = _run(screenshot_main, [*argv, str(tmp_path / "elsewhere")])
    assert status == 0, err


def test_urdf_check_reports_every_file(tmp_path: Path) -> None:
    status, out, _ = _run(urdf_check_main, [str(CORPUS)])
    assert status == 1  # two files fail, one draws nothing
    assert out.splitlines()[-1] == (
        "19 URDF files: 2 loaded cleanly, 14 loaded with warnings, 1 loaded with nothing to "
        "draw, 2 failed"
    )
    assert re.search(r"^FAILED  cycle.urdf: no root link; joints form a cycle", out, re.M)
    assert re.search(r"^EMPTY   only_degenerate_geometry.urdf: .*\n +nothing to draw", out, re.M)
    assert re.search(
        r"^warned  commas_in_xyz.urdf: 2 links, 1 moving joints, 24 triangles .*\n"
        r" +- line 13: joint 'j' origin xyz='0.07, 0, -0.69': commas",
        out,
        re.M,
    )
    good = tmp_path / "good"
    good.mkdir()
    shutil.copy(CORPUS / "xacro_namespace_and_comment.urdf", good / "a.urdf")
    status, out, _ = _run(urdf_check_main, [str(good)])
    assert status == 0
    assert out.startswith("loaded  a.urdf: 2 links")
    status, _, err = _run(urdf_check_main, [str(tmp_path / "none")])
    assert status == 2
    assert "no such file or folder" in err
