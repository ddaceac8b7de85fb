"""The simulator's world: the file format and its errors, collisions, ray casting."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from ocu.nav.geometry import Pose, advance, compose, relative
from ocu.nav.world import (
    DEFAULT_WORLD,
    WorldError,
    load_world,
    overlapping,
    parse_world,
)
from ocu.profile import Footprint, RobotProfile

SQUARE = {
    "name": "square",
    "wall": [
        {"from_m": [-2.0, -2.0], "to_m": [2.0, -2.0]},
        {"from_m": [2.0, -2.0], "to_m": [2.0, 2.0]},
        {"from_m": [2.0, 2.0], "to_m": [-2.0, 2.0]},
        {"from_m": [-2.0, 2.0], "to_m": [-2.0, -2.0]},
    ],
    "box": [{"centre_m": [1.0, 0.0], "size_m": [0.2, 0.4], "yaw_deg": 0.0}],
}


def test_the_default_room_loads_and_its_start_is_free(profile: RobotProfile) -> None:
    world = load_world(DEFAULT_WORLD)
    assert world.name == "default room"
    assert len(world.obstacles) >= 5
    footprint = profile.navigation.footprint
    assert footprint is not None
    assert world.touching(footprint, world.start) is None


def test_ray_cast_measures_the_distance_to_the_nearest_edge() -> None:
    world = parse_world(SQUARE)
    angles = np.array([0.0, math.pi / 2, math.pi, -math.pi / 2, math.pi / 4])
    ranges = world.ray_cast((0.0, 0.0), angles, 8.0)
    # The box's near face at x = 0.9; the walls' inner faces at 2 - 0.05.
    assert ranges == pytest.approx([0.9, 1.95, 1.95, 1.95, 1.95 * math.sqrt(2)], abs=1e-9)
    assert math.isinf(world.ray_cast((0.0, 0.0), np.array([0.0]), 0.5)[0])


def test_footprint_collision_follows_the_pose() -> None:
    world = parse_world(SQUARE)
    footprint = Footprint(front_m=0.3, rear_m=0.3, half_width_m=0.2)
    assert world.touching(footprint, Pose(0.0, 0.0, 0.0)) is None
    # Front edge at 0.61 + 0.3, past the box face at 0.9.
    touched = world.touching(footprint, Pose(0.61, 0.0, 0.0))
    assert touched is not None
    assert touched.kind == "box"
    assert world.touching(footprint, Pose(0.59, 0.0, 0.0)) is None
    # Turned 90 degrees, the same spot reaches only 0.6 + 0.2 < 0.9.
    assert world.touching(footprint, Pose(0.6, 0.0, math.pi / 2)) is None
    # Turned so its front-left corner points along +x, that corner finds the wall first.
    corner, turn = math.hypot(0.3, 0.2), -math.atan2(0.2, 0.3)
    assert world.touching(footprint, Pose(1.95 - corner - 0.01, -1.0, turn)) is None
    assert world.touching(footprint, Pose(1.95 - corner + 0.01, -1.0, turn)) is not None


def test_overlap_of_rectangles_by_separating_axes() -> None:
    square = np.array([[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]])
    diamond = np.array([[[2.2, 0.0], [1.1, 1.1], [0.0, 0.0], [1.1, -1.1]]])
    assert overlapping(square, diamond).tolist() == [True]
    assert overlapping(square, diamond + np.array([1.05, 0.0])).tolist() == [False]


def test_poses_compose_and_arcs_are_exact() -> None:
    a = Pose(1.0, 2.0, 0.5)
    b = Pose(-0.3, 0.7, -1.2)
    assert compose(a, relative(a, b)) == pytest.approx(b)
    quarter = advance(Pose(0.0, 0.0, 0.0), math.pi / 2, math.pi / 2)
    assert quarter == pytest.approx((1.0, 1.0, math.pi / 2))


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('nmae = "x"\n', r"world\.nmae: unknown key; did you mean 'name'\?"),
        ("[[wall]]\nfrom_m = [0, 0]\nto_m = [0, 0]\n", r"wall\[0\]: from_m and to_m are the same"),
        ("[[wall]]\nfrom_m = [0, 0]\n", r"wall\[0\]\.to_m: missing"),
        ("[[box]]\ncentre_m = [0, 0]\nsize_m = [1, -1]\n", r"box\[0\]\.size_m: both sides"),
        (
            "[[box]]\ncentre_m = [0, 0]\nsize_m = [1, 1]\ncolor = [1, 2, 3]\n",
            r"did you mean 'colour'",
        ),
        ("[[box]]\ncentre_m = [0, 'a']\nsize_m = [1, 1]\n", r"centre_m: must be two finite"),
        ("[start]\nheading_deg = nan\n", r"start\.heading_deg: must be a finite number"),
        ("wall = 3\n", r"world\.wall: must be an array of tables"),
        ("[[wall\n", r"not valid TOML"),
    ],
)
def test_bad_world_files_are_refused_by_name(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(WorldError, match=message):
        load_world(path)


def test_a_missing_world_file_is_named(tmp_path: Path) -> None:
    with pytest.raises(WorldError, match=r"cannot read world .*absent\.toml"):
        load_world(tmp_path / "absent.toml")
