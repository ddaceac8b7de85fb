"""OSMesa rendering: real pictures, checked against the kinematics instead of golden PNGs."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest
from PIL import Image

from ocu.model.tree import KinematicTree
from ocu.model.urdf import RobotModel
from ocu.render.camera import OrbitCamera
from ocu.render.offscreen import OffscreenRenderer
from ocu.render.renderer import interleave
from ocu.render.scene import BACKGROUND, build_frame
from ocu.render.screenshot import main as screenshot_main

Image_ = npt.NDArray[np.uint8]
WIDTH, HEIGHT = 320, 240
CHECKED_LINKS = ("upper_arm", "forearm", "head", "turret")


def _background() -> npt.NDArray[np.int64]:
    return np.round(np.asarray(BACKGROUND[:3]) * 255).astype(np.int64)


def _not_background(image: Image_) -> npt.NDArray[np.bool_]:
    return bool_mask(np.abs(image[:, :, :3].astype(np.int64) - _background()).sum(axis=2) > 12)


def bool_mask(values: npt.NDArray[np.bool_]) -> npt.NDArray[np.bool_]:
    return np.asarray(values, dtype=bool)


def _fixed_camera(view: str) -> OrbitCamera:
    """One framing for every pose, so that motion shows as motion on screen."""
    return OrbitCamera.framing((-0.7, -0.7, 0.0), (1.0, 0.7, 1.2), view)


def _pose(engineer: RobotModel, **degrees: float) -> KinematicTree:
    tree = engineer.tree.copy()
    tree.set_positions({name: math.radians(value) for name, value in degrees.items()})
    return tree


def _id_colors(engineer: RobotModel) -> dict[str, tuple[float, float, float, float]]:
    """A distinct flat colour per link; checked links get easy-to-tell primaries."""
    colors: dict[str, tuple[float, float, float, float]] = {}
    for index, link in enumerate(engineer.tree.links):
        colors[link] = ((index * 13 % 256) / 255.0, 40 / 255.0, 40 / 255.0, 1.0)
    colors.update(
        upper_arm=(1.0, 0.0, 0.0, 1.0),
        forearm=(0.0, 1.0, 0.0, 1.0),
        head=(0.0, 0.0, 1.0, 1.0),
        turret=(1.0, 1.0, 0.0, 1.0),
    )
    return colors


def test_default_render_is_not_blank(offscreen: OffscreenRenderer, engineer: RobotModel) -> None:
    tree = _pose(engineer, shoulder=45, elbow=60)
    image = offscreen.render(build_frame(engineer, _fixed_camera("iso"), WIDTH / HEIGHT, live=tree))
    assert image.shape == (HEIGHT, WIDTH, 4)
    covered = _not_background(image).mean()
    assert 0.05 < covered < 0.95
    colors = {tuple(c) for c in image[:, :, :3].reshape(-1, 3)[::7].tolist()}
    assert len(colors) > 50  # shaded, not flat


@pytest.mark.parametrize(
    ("view", "pose"),
    [
        ("side", {"shoulder": 30, "elbow": 60}),
        ("side", {"shoulder": 100, "elbow": 120, "neck": -30}),
        ("side", {"shoulder": 10, "elbow": -80, "neck": 40}),
        ("top", {"waist": 90, "shoulder": 20, "elbow": 20}),
        ("front", {"waist": -60, "shoulder": 60, "elbow": 90}),
    ],
)
def test_arm_silhouette_is_where_the_kinematics_put_it(
    offscreen: OffscreenRenderer, engineer: RobotModel, view: str, pose: dict[str, float]
) -> None:
    tree = _pose(engineer, **pose)
    camera = _fixed_camera(view)
    colors = _id_colors(engineer)
    frame = build_frame(engineer, camera, WIDTH / HEIGHT, live=tree, flat_colors=colors)
    image = offscreen.render(frame)[:, :, :3].astype(np.int64)
    world = tree.world_transforms()
    for link in CHECKED_LINKS:
        centre = world[link] @ np.append(engineer.meshes[link].center(), 1.0)
        expected_x, expected_y = camera.project([centre[:3]], WIDTH, HEIGHT)[0]
        want = np.round(np.asarray(colors[link][:3]) * 255).astype(np.int64)
        mask = (image == want).all(axis=2)
        assert mask.sum() > 15, f"{link} is not visible in {view} view at {pose}"
        ys, xs = np.nonzero(mask)
        centroid = (xs.mean() + 0.5, ys.mean() + 0.5)
        assert math.dist(centroid, (expected_x, expected_y)) < 10.0, (
            f"{link}: drawn around {centroid}, kinematics say ({expected_x:.1f}, "
            f"{expected_y:.1f}) in {view} view at {pose}"
        )


def test_moving_a_joint_moves_the_picture_not_the_vertices(
    offscreen: OffscreenRenderer, engineer: RobotModel
) -> None:
    renderer = offscreen.renderer
    uploads = renderer.buffer_uploads
    assert uploads == sum(1 for m in engineer.meshes.values() if m.vertex_count) + 1  # + grid
    camera = _fixed_camera("side")
    tree = engineer.tree.copy()
    first = offscreen.render(build_frame(engineer, camera, WIDTH / HEIGHT, live=tree))
    rng = np.random.default_rng(3)
    for _ in range(20):
        tree.set_positions({"shoulder": rng.uniform(0, 2), "elbow": rng.uniform(-2, 2)})
        last = offscreen.render(build_frame(engineer, camera, WIDTH / HEIGHT, live=tree))
    assert renderer.buffer_uploads == uploads
    assert renderer.read_buffer("forearm") == interleave(engineer.meshes["forearm"]).tobytes()
    assert (first != last).any()


def test_stale_links_are_amber_and_the_ghost_is_translucent_blue(
    offscreen: OffscreenRenderer, engineer: RobotModel
) -> None:
    camera = _fixed_camera("side")
    live = _pose(engineer, shoulder=20, elbow=20)
    ghost = _pose(engineer, shoulder=100, elbow=20)

    def pixel_at(image: Image_, tree: KinematicTree, link: str) -> npt.NDArray[np.int64]:
        world = tree.world_transforms()[link]
        centre = world @ np.append(engineer.meshes[link].center(), 1.0)
        x, y = camera.project([centre[:3]], WIDTH, HEIGHT)[0]
        patch = image[int(y) - 1 : int(y) + 2, int(x) - 1 : int(x) + 2, :3]
        return np.asarray(patch.reshape(-1, 3).mean(axis=0), dtype=np.int64)

    plain = offscreen.render(build_frame(engineer, camera, WIDTH / HEIGHT, live=live))
    r, g, b = pixel_at(plain, live, "upper_arm")
    assert abs(r - g) < 20
    assert abs(g - b) < 20
    stale = offscreen.render(
        build_frame(engineer, camera, WIDTH / HEIGHT, live=live, stale_joints={"shoulder"})
    )
    r, g, b = pixel_at(stale, live, "upper_arm")
    assert r > g + 40
    assert g > b + 30
    r, g, b = pixel_at(stale, live, "forearm")
    assert abs(r - g) < 20  # only the link the stale joint carries
    with_ghost = offscreen.render(
        build_frame(engineer, camera, WIDTH / HEIGHT, live=live, ghost=ghost)
    )
    background = _background()
    r, g, b = pixel_at(with_ghost, ghost, "upper_arm")
    assert b > r + 30
    assert b > background[2] + 20
    r, g, b = pixel_at(plain, ghost, "upper_arm")
    assert np.abs(np.array([r, g, b]) - background).max() < 15  # nothing there without it


def test_grid_and_axes_are_drawn_unless_turned_off(
    offscreen: OffscreenRenderer, engineer: RobotModel
) -> None:
    camera = _fixed_camera("top")
    raised = _pose(engineer, shoulder=90)  # out of the way of the x axis
    with_grid = offscreen.render(build_frame(engineer, camera, WIDTH / HEIGHT, live=raised))
    for point, channel in (((0.45, 0.0, 0.0), 0), ((0.0, 0.42, 0.0), 1)):
        x, y = (int(v) for v in camera.project([point], WIDTH, HEIGHT)[0])
        patch = with_grid[y - 1 : y + 2, x - 1 : x + 2, :3].astype(np.int64)
        others = np.delete(patch, channel, axis=2).max(axis=2)
        assert (patch[:, :, channel] > others + 60).any(), f"no axis line at {point}"
    bare = offscreen.render(
        build_frame(engineer, camera, WIDTH / HEIGHT, live=raised, show_grid=False)
    )
    assert _not_background(bare).sum() < _not_background(with_grid).sum()


def test_screenshot_command_writes_a_png(tmp_path: Path) -> None:
    out = tmp_path / "shots" / "engineer.png"
    status = screenshot_main(
        [str(out), "--joints", "shoulder=60", "elbow=80", "--size", "200x150", "--view", "side"]
    )
    assert status == 0
    with Image.open(out) as image:
        assert image.size == (200, 150)
        pixels = np.asarray(image.convert("RGB"))
    assert _not_background(pixels).mean() > 0.05


def test_screenshot_command_reports_bad_arguments(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "x.png"
    assert screenshot_main([str(out), "--joints", "knee=10"]) == 1
    assert "unknown joint 'knee'; joints: flippers, waist" in capsys.readouterr().err
    assert screenshot_main([str(out), "--joints", "elbow"]) == 1
    assert "expected name=degrees" in capsys.readouterr().err
    assert screenshot_main([str(out), "--size", "big"]) == 1
    assert "expected WIDTHxHEIGHT" in capsys.readouterr().err
    assert screenshot_main([str(out), "--urdf", str(tmp_path / "none.urdf")]) == 1
    assert "cannot read URDF" in capsys.readouterr().err
    assert not out.exists()


def test_screenshot_of_a_collision_only_robot_with_a_prismatic_joint(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Prismatic values are metres, limit notes say so; collision geometry is drawn and the
    note says it is."""
    urdf = tmp_path / "slider.urdf"
    urdf.write_text(
        '<robot name="slider">'
        '<link name="rail"><collision><geometry><box size="1 0.1 0.1"/></geometry></collision>'
        "</link>"
        '<link name="carriage"><collision><geometry><box size="0.2 0.2 0.2"/></geometry>'
        "</collision></link>"
        '<joint name="slide" type="prismatic"><parent link="rail"/><child link="carriage"/>'
        '<axis xyz="1 0 0"/><limit lower="0" upper="0.3"/></joint></robot>'
    )
    out = tmp_path / "slider.png"
    status = screenshot_main(
        [str(out), "--urdf", str(urdf), "--joints", "slide=0.35", "--size", "160x120"]
    )
    assert status == 0
    err = capsys.readouterr().err
    assert "collision geometry is drawn instead" in err
    assert "slide=0.35 m is outside its limits [0 m, 0.3 m]" in err
    with Image.open(out) as image:
        pixels = np.asarray(image.convert("RGB"))
    assert _not_background(pixels).mean() > 0.02
