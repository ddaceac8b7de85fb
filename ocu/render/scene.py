"""What one frame shows: link transforms, tints and the ghost, built from the trees (no GL)."""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ocu.model.mesh import Rgba
from ocu.model.tree import KinematicTree, Matrix
from ocu.model.urdf import RobotModel
from ocu.render.camera import OrbitCamera

BACKGROUND: Rgba = (0.20, 0.22, 0.25, 1.0)
WARNING_TINT: Rgba = (1.0, 0.55, 0.0, 0.75)  # rgb and how much of it replaces the colour
GHOST_TINT: Rgba = (0.35, 0.75, 1.0, 0.6)
GHOST_ALPHA = 0.35
GHOST_TOLERANCE = 1e-6
# The pose of the last reading, behind the predicted one: faint and colourless.
READING_TINT: Rgba = (0.85, 0.85, 0.85, 0.8)
READING_ALPHA = 0.22
# A joint whose reading the OCU does not believe.
FAULT_TINT: Rgba = (0.9, 0.1, 0.1, 0.85)


@dataclass(frozen=True)
class LinkDraw:
    """One link mesh to draw: its absolute transform and an optional tint."""

    link: str
    world: Matrix
    tint: Rgba | None = None


@dataclass(frozen=True)
class OverlayDraw:
    """A helper drawn over the robot (a frame's axes, an arrow, the workspace): the name of a
    mesh given to the renderer, its transform, and how it is drawn."""

    mesh: str
    world: Matrix
    alpha: float = 1.0
    # Drawn through everything (a frame's axes inside the gripper stay visible).
    on_top: bool = False


@dataclass(frozen=True)
class RenderFrame:
    """Everything the renderer needs for one image."""

    view: Matrix
    projection: Matrix
    eye: tuple[float, float, float]
    links: Sequence[LinkDraw]
    ghosts: Sequence[LinkDraw] = ()
    ghost_alpha: float = GHOST_ALPHA
    # Where the last reading put the links that the prediction has moved since.
    readings: Sequence[LinkDraw] = ()
    reading_alpha: float = READING_ALPHA
    background: Rgba = BACKGROUND
    show_grid: bool = True
    lit: bool = True
    overlays: Sequence[OverlayDraw] = ()


def stale_links(tree: KinematicTree, stale_joints: Collection[str]) -> frozenset[str]:
    """Links carried directly by a stale joint or by a joint that mimics one."""
    links: set[str] = set()
    for joint in stale_joints:
        if joint in tree.joints:
            links.update(tree.links_moved_by(joint))
    return frozenset(links)


def ghost_links(live: KinematicTree, ghost: KinematicTree) -> list[str]:
    """Links whose pose in the ghost differs from the live pose."""
    live_world = live.world_array()
    ghost_world = ghost.world_array()
    differs = np.abs(live_world - ghost_world).max(axis=(1, 2)) > GHOST_TOLERANCE
    return [name for name, flag in zip(live.links, differs, strict=True) if flag]


def build_frame(
    model: RobotModel,
    camera: OrbitCamera,
    aspect: float,
    *,
    live: KinematicTree | None = None,
    ghost: KinematicTree | None = None,
    stale_joints: Collection[str] = (),
    show_grid: bool = True,
    flat_colors: Mapping[str, Rgba] | None = None,
    reading: KinematicTree | None = None,
    fault_joints: Collection[str] = (),
    overlays: Sequence[OverlayDraw] = (),
) -> RenderFrame:
    """A frame of the live pose, tinted where stale or implausible, with the ghost and the
    last reading's pose where they differ from it.

    With `flat_colors` every link is drawn unlit in one colour (links not named are left
    out): an ID image for picking and for tests that find a link's pixels.
    """
    tree = live or model.tree
    world = tree.world_transforms()
    warn = stale_links(tree, stale_joints)
    faulty = stale_links(tree, fault_joints)
    links: list[LinkDraw] = []
    for name in tree.links:
        if model.meshes[name].vertex_count == 0:
            continue
        if flat_colors is not None:
            if name in flat_colors:
                links.append(LinkDraw(name, world[name].copy(), flat_colors[name]))
            continue
        tint = FAULT_TINT if name in faulty else WARNING_TINT if name in warn else None
        links.append(LinkDraw(name, world[name].copy(), tint))
    ghosts: list[LinkDraw] = []
    readings: list[LinkDraw] = []
    if flat_colors is None:
        for other, tint, out in ((ghost, GHOST_TINT, ghosts), (reading, READING_TINT, readings)):
            if other is None:
                continue
            other_world = other.world_transforms()
            out.extend(
                LinkDraw(name, other_world[name].copy(), tint)
                for name in ghost_links(tree, other)
                if model.meshes[name].vertex_count > 0
            )
    eye = camera.eye()
    return RenderFrame(
        view=camera.view_matrix(),
        projection=camera.projection_matrix(aspect),
        eye=(float(eye[0]), float(eye[1]), float(eye[2])),
        links=links,
        ghosts=ghosts,
        readings=readings,
        show_grid=show_grid and flat_colors is None,
        lit=flat_colors is None,
        overlays=tuple(overlays) if flat_colors is None else (),
    )


def model_bounds(model: RobotModel, tree: KinematicTree | None = None) -> tuple[Matrix, Matrix]:
    """Axis-aligned world box around every link in the tree's current pose."""
    world = (tree or model.tree).world_transforms()
    corners = []
    for name, mesh in model.meshes.items():
        if mesh.vertex_count == 0:
            continue
        low, high = mesh.bounds()
        box = np.array(
            [
                [x, y, z, 1.0]
                for x in (low[0], high[0])
                for y in (low[1], high[1])
                for z in (low[2], high[2])
            ]
        )
        corners.append((box @ world[name].T)[:, :3])
    if not corners:
        return np.zeros(3), np.zeros(3)
    points = np.vstack(corners)
    return points.min(axis=0), points.max(axis=0)
