"""Helper meshes drawn over the robot (no GL): a frame's axes, an arrow, a goal marker.

Each is a `MeshData` in its own unit frame; a frame's `OverlayDraw.world` places and scales it.
"""

from __future__ import annotations

import numpy as np

from ocu.model.mesh import MeshData

AXIS_COLORS = (
    (230, 60, 50, 255),
    (70, 200, 80, 255),
    (70, 120, 240, 255),
)  # x red, y green, z blue
ARROW_COLOR = (255, 200, 40, 255)
GOAL_COLOR = (60, 190, 255, 255)


def _lines(
    points: list[tuple[float, float, float]], colors: list[tuple[int, int, int, int]]
) -> MeshData:
    positions = np.asarray(points, dtype=np.float32).reshape(-1, 3)
    return MeshData(
        positions=positions,
        normals=np.zeros_like(positions),
        colors=np.asarray(colors, dtype=np.uint8).reshape(-1, 4),
    )


def axes_mesh(length_m: float = 0.08) -> MeshData:
    """Three lines from the origin: x red, y green, z blue."""
    points: list[tuple[float, float, float]] = []
    colors: list[tuple[int, int, int, int]] = []
    for axis, color in enumerate(AXIS_COLORS):
        end = [0.0, 0.0, 0.0]
        end[axis] = length_m
        points += [(0.0, 0.0, 0.0), (end[0], end[1], end[2])]
        colors += [color, color]
    return _lines(points, colors)


def arrow_mesh() -> MeshData:
    """A unit arrow along +x: a shaft and a four-line head (scale it to the length wanted)."""
    head = 0.25
    points = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0)]
    for dy, dz in ((1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)):
        points += [(1.0, 0.0, 0.0), (1.0 - head, head * 0.5 * dy, head * 0.5 * dz)]
    return _lines(points, [ARROW_COLOR] * len(points))


def marker_mesh(radius_m: float = 0.03) -> MeshData:
    """A small octahedron's edges and a cross through it: where a goal puts tool0."""
    r = radius_m
    tips = [
        (r, 0.0, 0.0),
        (-r, 0.0, 0.0),
        (0.0, r, 0.0),
        (0.0, -r, 0.0),
        (0.0, 0.0, r),
        (0.0, 0.0, -r),
    ]
    points: list[tuple[float, float, float]] = []
    for a in range(6):
        for b in range(a + 1, 6):
            if a // 2 != b // 2:
                points += [tips[a], tips[b]]
    for a in range(0, 6, 2):
        points += [tips[a], tips[a + 1]]
    return _lines(points, [GOAL_COLOR] * len(points))
