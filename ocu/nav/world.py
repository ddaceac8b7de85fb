"""The simulator's world: walls and boxes from a TOML file in metres (docs/navigation.md).

Everything is an upright box seen from above: a wall is a long, thin one from one point to
another. The world answers what the simulator needs — whether the robot's footprint touches
anything (collision), how far each beam of a planar range sensor reaches (ray casting) — and
what the cameras draw (ocu.sim.scene). Pure numpy, no Qt.

    name = "default room"
    [start]                      # where the robot starts (optional: the origin)
    xy_m = [0.0, 0.0]
    heading_deg = 0.0
    [[wall]]
    from_m = [-4.0, -3.0]
    to_m = [4.0, -3.0]
    thickness_m = 0.1            # optional, 0.1
    height_m = 1.0               # optional, 1.0
    [[box]]
    centre_m = [2.0, 1.0]
    size_m = [0.6, 0.4]          # along x and y before the yaw
    yaw_deg = 0.0                # optional
    height_m = 0.5               # optional
    colour = [200, 120, 60]      # optional, RGB
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ocu.nav.geometry import ORIGIN, Points, Pose, to_world
from ocu.profile import Footprint, did_you_mean

DEFAULT_WORLD = "default"
WALL_THICKNESS_M = 0.1
WALL_HEIGHT_M = 1.0
BOX_HEIGHT_M = 0.5
WALL_COLOUR_RGB = (205, 200, 190)
BOX_COLOUR_RGB = (190, 120, 60)
TOP_KEYS = ("name", "start", "wall", "box")
START_KEYS = ("xy_m", "heading_deg")
WALL_KEYS = ("from_m", "to_m", "thickness_m", "height_m", "colour")
BOX_KEYS = ("centre_m", "size_m", "yaw_deg", "height_m", "colour")
MAX_OBSTACLES = 1000
MAX_EXTENT_M = 1000.0


class WorldError(ValueError):
    """A world file that cannot be read, or a value in it that makes no sense."""


@dataclass(frozen=True)
class Obstacle:
    """An upright box: centre, half sizes along its own axes, yaw, height and colour."""

    kind: str
    centre_m: tuple[float, float]
    half_size_m: tuple[float, float]
    yaw_rad: float
    height_m: float
    colour_rgb: tuple[int, int, int]

    @property
    def corners_m(self) -> Points:
        """(4, 2) corners counter-clockwise."""
        hx, hy = self.half_size_m
        local = np.array([[hx, hy], [-hx, hy], [-hx, -hy], [hx, -hy]])
        return to_world(local, Pose(self.centre_m[0], self.centre_m[1], self.yaw_rad))


@dataclass(frozen=True)
class World:
    """Obstacles and the robot's start pose; `source` names the file it came from."""

    name: str
    obstacles: tuple[Obstacle, ...]
    start: Pose = ORIGIN
    source: str = "<world>"
    _corners: npt.NDArray[np.float64] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        corners = (
            np.stack([o.corners_m for o in self.obstacles])
            if self.obstacles
            else np.zeros((0, 4, 2))
        )
        object.__setattr__(self, "_corners", corners)

    @property
    def corners_m(self) -> npt.NDArray[np.float64]:
        """(K, 4, 2) corners of every obstacle."""
        return self._corners

    @property
    def segments_m(self) -> npt.NDArray[np.float64]:
        """(4K, 2, 2) edges of every obstacle, as (start, end) points."""
        corners = self._corners
        return np.stack([corners, np.roll(corners, -1, axis=1)], axis=2).reshape(-1, 2, 2)

    def bounds_m(self) -> tuple[float, float, float, float]:
        """(x_min, y_min, x_max, y_max) of everything in the world and its start."""
        if not self.obstacles:
            return (self.start.x_m, self.start.y_m, self.start.x_m, self.start.y_m)
        flat = self._corners.reshape(-1, 2)
        low, high = flat.min(axis=0), flat.max(axis=0)
        return (float(low[0]), float(low[1]), float(high[0]), float(high[1]))

    def touching(self, footprint: Footprint, pose: Pose) -> Obstacle | None:
        """The first obstacle the footprint at `pose` overlaps, or None (separating axes)."""
        if not self.obstacles:
            return None
        hit = overlapping(footprint_corners(footprint, pose), self._corners)
        index = int(np.argmax(hit))
        return self.obstacles[index] if hit[index] else None

    def ray_cast(
        self, origin: tuple[float, float], angles_rad: npt.NDArray[np.float64], max_range_m: float
    ) -> npt.NDArray[np.float64]:
        """Distance along each beam to the first obstacle edge; inf beyond max_range_m."""
        angles = np.asarray(angles_rad, dtype=np.float64)
        result = np.full(angles.shape, math.inf)
        if not self.obstacles:
            return result
        segments = self.segments_m
        start, end = segments[:, 0, :], segments[:, 1, :]
        edge = end - start  # (M, 2)
        direction = np.stack([np.cos(angles), np.sin(angles)], axis=-1)  # (N, 2)
        to_start = start - np.asarray(origin, dtype=np.float64)  # (M, 2)
        denom = _cross(direction[:, None, :], edge[None, :, :])  # (N, M)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = _cross(to_start[None, :, :], edge[None, :, :]) / denom
            u = _cross(to_start[None, :, :], direction[:, None, :]) / denom
        valid = (np.abs(denom) > 1e-12) & (t >= 0.0) & (u >= 0.0) & (u <= 1.0)
        t = np.where(valid, t, math.inf)
        nearest = t.min(axis=1)
        result = np.where(nearest <= max_range_m, nearest, math.inf)
        return np.asarray(result, dtype=np.float64)


def _cross(a: npt.NDArray[np.float64], b: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    return np.asarray(a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0], dtype=np.float64)


def footprint_corners(footprint: Footprint, pose: Pose) -> Points:
    """(4, 2) corners of the footprint at a pose."""
    return to_world(np.array(footprint.corners_m, dtype=np.float64), pose)


def overlapping(polygon: Points, boxes: npt.NDArray[np.float64]) -> npt.NDArray[np.bool_]:
    """Which of the (K, 4, 2) boxes a convex (4, 2) rectangle overlaps (touching counts)."""
    if len(boxes) == 0:
        return np.zeros(0, dtype=bool)
    poly_edges = np.roll(polygon, -1, axis=0) - polygon  # (4, 2)
    box_edges = np.roll(boxes, -1, axis=1) - boxes  # (K, 4, 2)
    # Rectangles: two edge normals each suffice.
    axes = np.concatenate(
        [np.broadcast_to(poly_edges[:2], (len(boxes), 2, 2)), box_edges[:, :2, :]], axis=1
    )
    normals = np.stack([-axes[..., 1], axes[..., 0]], axis=-1)  # (K, 4, 2)
    poly_proj = np.einsum("kad,pd->kap", normals, polygon)  # (K, 4 axes, 4 points)
    box_proj = np.einsum("kad,kpd->kap", normals, boxes)
    separated = (poly_proj.max(axis=2) < box_proj.min(axis=2)) | (
        box_proj.max(axis=2) < poly_proj.min(axis=2)
    )
    return np.asarray(~separated.any(axis=1))


# ---- reading a world file ----------------------------------------------------------------


def default_world_path() -> Path:
    """The room shipped with the simulator (ocu/sim/worlds/room.toml)."""
    return Path(str(resources.files("ocu") / "sim" / "worlds" / "room.toml"))


def load_world(path: str | Path) -> World:
    """Read and check a world file; `DEFAULT_WORLD` names the shipped room."""
    world_path = default_world_path() if str(path) == DEFAULT_WORLD else Path(path)
    try:
        text = world_path.read_text(encoding="utf-8")
    except OSError as err:
        raise WorldError(f"cannot read world {world_path}: {err.strerror}") from err
    except UnicodeDecodeError as err:
        raise WorldError(f"{world_path}: not UTF-8 text: {err}") from err
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise WorldError(f"{world_path}: not valid TOML: {err}") from err
    return parse_world(data, str(world_path))


def _keys(table: dict[str, Any], allowed: tuple[str, ...], where: str) -> None:
    for key in table:
        if key not in allowed:
            raise WorldError(f"{where}.{key}: unknown key; {did_you_mean(key, allowed)}")


def _number(table: dict[str, Any], key: str, where: str, default: float | None = None) -> float:
    if key not in table:
        if default is None:
            raise WorldError(f"{where}.{key}: missing")
        return default
    value = table[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise WorldError(f"{where}.{key}: must be a finite number, got {value!r}")
    return float(value)


def _pair(table: dict[str, Any], key: str, where: str) -> tuple[float, float]:
    if key not in table:
        raise WorldError(f"{where}.{key}: missing")
    value = table[key]
    if (
        not isinstance(value, list)
        or len(value) != 2
        or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
            for v in value
        )
    ):
        raise WorldError(f"{where}.{key}: must be two finite numbers [x, y], got {value!r}")
    if any(abs(v) > MAX_EXTENT_M for v in value):
        raise WorldError(f"{where}.{key}: {value!r} is more than {MAX_EXTENT_M:g} m out")
    return float(value[0]), float(value[1])


def _colour(table: dict[str, Any], where: str, default: tuple[int, int, int]) -> tuple[int, ...]:
    if "colour" not in table:
        return default
    value = table["colour"]
    if (
        not isinstance(value, list)
        or len(value) != 3
        or not all(isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= 255 for v in value)
    ):
        raise WorldError(f"{where}.colour: must be [R, G, B] with 0-255 each, got {value!r}")
    return tuple(value)


def _positive(table: dict[str, Any], key: str, where: str, default: float) -> float:
    value = _number(table, key, where, default)
    if value <= 0.0:
        raise WorldError(f"{where}.{key}: must be > 0, got {value!r}")
    return value


def _list(data: dict[str, Any], key: str) -> list[dict[str, Any]]:
    items = data.get(key, [])
    if not isinstance(items, list) or not all(isinstance(item, dict) for item in items):
        raise WorldError(f"world.{key}: must be an array of tables ([[{key}]])")
    return items


def parse_world(data: dict[str, Any], source: str = "<world>") -> World:
    """Check a decoded world file and build the World."""
    _keys(data, TOP_KEYS, "world")
    name = data.get("name", Path(source).stem)
    if not isinstance(name, str) or not name:
        raise WorldError("world.name: must be a non-empty string")
    start = ORIGIN
    if "start" in data:
        table = data["start"]
        if not isinstance(table, dict):
            raise WorldError("world.start: must be a table")
        _keys(table, START_KEYS, "world.start")
        x, y = _pair(table, "xy_m", "world.start") if "xy_m" in table else (0.0, 0.0)
        heading = math.radians(_number(table, "heading_deg", "world.start", 0.0))
        start = Pose(x, y, heading)
    obstacles: list[Obstacle] = []
    for index, wall in enumerate(_list(data, "wall")):
        where = f"world.wall[{index}]"
        _keys(wall, WALL_KEYS, where)
        a, b = _pair(wall, "from_m", where), _pair(wall, "to_m", where)
        length = math.dist(a, b)
        if length <= 0.0:
            raise WorldError(f"{where}: from_m and to_m are the same point")
        thickness = _positive(wall, "thickness_m", where, WALL_THICKNESS_M)
        colour = _colour(wall, where, WALL_COLOUR_RGB)
        obstacles.append(
            Obstacle(
                kind="wall",
                centre_m=((a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0),
                half_size_m=(length / 2.0, thickness / 2.0),
                yaw_rad=math.atan2(b[1] - a[1], b[0] - a[0]),
                height_m=_positive(wall, "height_m", where, WALL_HEIGHT_M),
                colour_rgb=(colour[0], colour[1], colour[2]),
            )
        )
    for index, box in enumerate(_list(data, "box")):
        where = f"world.box[{index}]"
        _keys(box, BOX_KEYS, where)
        size = _pair(box, "size_m", where)
        if min(size) <= 0.0:
            raise WorldError(f"{where}.size_m: both sides must be > 0, got {list(size)}")
        colour = _colour(box, where, BOX_COLOUR_RGB)
        obstacles.append(
            Obstacle(
                kind="box",
                centre_m=_pair(box, "centre_m", where),
                half_size_m=(size[0] / 2.0, size[1] / 2.0),
                yaw_rad=math.radians(_number(box, "yaw_deg", where, 0.0)),
                height_m=_positive(box, "height_m", where, BOX_HEIGHT_M),
                colour_rgb=(colour[0], colour[1], colour[2]),
            )
        )
    if len(obstacles) > MAX_OBSTACLES:
        raise WorldError(f"world: {len(obstacles)} walls and boxes; at most {MAX_OBSTACLES}")
    return World(name=name, obstacles=tuple(obstacles), start=start, source=source)


EMPTY_WORLD = World(name="open plane", obstacles=())
