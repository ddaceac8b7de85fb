"""What a camera on the robot sees of the simulator's world: a pinhole projection with OpenCV.

`WorldView.render(pose, mount, size_px, focal_px, centre_px)` draws, for a camera mounted on
the chassis (ocu.profile.CameraMount) of a robot at `pose`, the floor with a 0.5 m grid (a
darker line every metre), the walls and the boxes as shaded upright boxes (far faces first),
and a horizon; nothing else. It is an ideal pinhole image: the simulator's cameras then pass
it through their lens model and colour cast (ocu.sim.extended). Pure numpy + cv2; reusable
by anything that needs to know what the cameras show (video tracking, tests).

Camera frame: x right, y down, z along the view; world frame: x, y on the floor, z up.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import cv2
import numpy as np
import numpy.typing as npt

from ocu.model.tree import KinematicTree
from ocu.nav.geometry import Pose
from ocu.nav.world import World
from ocu.profile import CameraMount

Image = npt.NDArray[np.uint8]
Matrix = npt.NDArray[np.float64]

NEAR_M = 0.05
FLOOR_GRID_M = 0.5
FLOOR_REACH_M = 10.0
SKY_BGR = (70, 62, 58)
FLOOR_BGR = (120, 128, 132)
GRID_BGR = (92, 98, 102)
GRID_MAJOR_BGR = (60, 64, 68)
EDGE_BGR = (30, 30, 30)
# Light from above and behind the viewer's left: faces turned to it are brighter.
LIGHT = np.array([0.4, 0.3, 0.86])
DEFAULT_MOUNT = CameraMount((0.35, 0.0, 0.25))
SUBPIXEL_BITS = 4


def _mount_axes(mount: CameraMount) -> Matrix:
    """The camera's right, down and forward axes (rows) in the frame it is mounted in."""
    yaw, pitch = mount.yaw_rad, mount.pitch_rad
    forward = np.array(
        [math.cos(yaw) * math.cos(pitch), math.sin(yaw) * math.cos(pitch), -math.sin(pitch)]
    )
    right = np.array([math.sin(yaw), -math.cos(yaw), 0.0])
    down = np.cross(forward, right)
    return np.stack([right, down, forward])


def _chassis(pose: Pose) -> Matrix:
    """base_link -> world (4x4) of a chassis at `pose` on the floor."""
    c, s = math.cos(pose.heading_rad), math.sin(pose.heading_rad)
    matrix = np.eye(4)
    matrix[:2, :2] = [[c, -s], [s, c]]
    matrix[0, 3], matrix[1, 3] = pose.x_m, pose.y_m
    return matrix


def camera_rotation(pose: Pose, mount: CameraMount, link: Matrix | None = None) -> Matrix:
    """World -> camera rotation for a camera on the chassis at `pose`; `link` is the 4x4
    base_link -> mount link transform of a camera on a moving link (None: on the chassis)."""
    frame = _chassis(pose) if link is None else _chassis(pose) @ link
    return _mount_axes(mount) @ frame[:3, :3].T


def camera_position(pose: Pose, mount: CameraMount, link: Matrix | None = None) -> Matrix:
    """Where the camera is in the world."""
    frame = _chassis(pose) if link is None else _chassis(pose) @ link
    position: Matrix = frame[:3, :3] @ np.array(mount.xyz_m) + frame[:3, 3]
    return position


class CameraLinks:
    """Where the links cameras are mounted on stand for given joint angles (URDF forward
    kinematics from base_link)."""

    def __init__(self, tree: KinematicTree, base_link: str = "base_link") -> None:
        self._tree = tree.copy()
        self.base_link = base_link
        if base_link not in self._tree.links:
            raise ValueError(f"the robot model has no link {base_link!r}")

    def has(self, link: str) -> bool:
        """Whether the model has this link."""
        return link in self._tree.links

    def transform(self, link: str, joints_rad: Mapping[str, float]) -> Matrix:
        """base_link -> `link` (4x4) with the model's joints at these angles (others at 0)."""
        actuated = self._tree.positions()
        self._tree.set_positions({name: float(joints_rad.get(name, 0.0)) for name in actuated})
        base = self._tree.world_transform(self.base_link)
        target = self._tree.world_transform(link)
        result: Matrix = np.linalg.inv(base) @ target
        return result


def _clip_polygon(points: Matrix) -> Matrix:
    """A polygon in camera coordinates clipped to z >= NEAR_M (Sutherland-Hodgman)."""
    out: list[Matrix] = []
    count = len(points)
    for k in range(count):
        a, b = points[k], points[(k + 1) % count]
        a_in, b_in = a[2] >= NEAR_M, b[2] >= NEAR_M
        if a_in:
            out.append(a)
        if a_in != b_in:
            t = (NEAR_M - a[2]) / (b[2] - a[2])
            out.append(a + t * (b - a))
    return np.array(out) if out else np.zeros((0, 3))


class WorldView:
    """Renders one world from cameras on the robot (see the module docstring)."""

    def __init__(self, world: World, links: CameraLinks | None = None) -> None:
        self.world = world
        # Forward kinematics for cameras mounted on a moving link (CameraMount.link).
        self.links = links
        self._faces = self._build_faces()
        self._grid = self._build_grid()

    def _build_faces(self) -> list[tuple[Matrix, Matrix, tuple[int, int, int]]]:
        """(corners (4, 3), outward normal, BGR) of every visible face of every obstacle."""
        faces = []
        for obstacle in self.world.obstacles:
            base = obstacle.corners_m  # (4, 2), counter-clockwise
            height = obstacle.height_m
            red, green, blue = obstacle.colour_rgb
            colour = (blue, green, red)
            for k in range(4):
                a, b = base[k], base[(k + 1) % 4]
                quad = np.array(
                    [
                        [a[0], a[1], 0.0],
                        [b[0], b[1], 0.0],
                        [b[0], b[1], height],
                        [a[0], a[1], height],
                    ]
                )
                edge = b - a
                normal = np.array([edge[1], -edge[0], 0.0])
                normal /= max(float(np.linalg.norm(normal)), 1e-12)
                faces.append((quad, normal, colour))
            top = np.column_stack([base, np.full(4, height)])
            faces.append((top, np.array([0.0, 0.0, 1.0]), colour))
        return faces

    def _build_grid(self) -> Matrix:
        """(L, 2, 3) floor grid lines around the world's extent."""
        x0, y0, x1, y1 = self.world.bounds_m()
        x0, y0 = min(x0, -FLOOR_REACH_M / 2), min(y0, -FLOOR_REACH_M / 2)
        x1, y1 = max(x1, FLOOR_REACH_M / 2), max(y1, FLOOR_REACH_M / 2)
        x0, y0 = (
            math.floor(x0 / FLOOR_GRID_M) * FLOOR_GRID_M,
            math.floor(y0 / FLOOR_GRID_M) * FLOOR_GRID_M,
        )
        x1, y1 = (
            math.ceil(x1 / FLOOR_GRID_M) * FLOOR_GRID_M,
            math.ceil(y1 / FLOOR_GRID_M) * FLOOR_GRID_M,
        )
        lines = [((x, y0, 0.0), (x, y1, 0.0)) for x in np.arange(x0, x1 + 1e-9, FLOOR_GRID_M)]
        lines += [((x0, y, 0.0), (x1, y, 0.0)) for y in np.arange(y0, y1 + 1e-9, FLOOR_GRID_M)]
        return np.array(lines, dtype=np.float64)

    def render(
        self,
        pose: Pose,
        mount: CameraMount | None,
        size_px: tuple[int, int],
        focal_px: tuple[float, float],
        centre_px: tuple[float, float] | None = None,
        *,
        joints_rad: Mapping[str, float] | None = None,
    ) -> Image:
        """The ideal pinhole image (BGR) of the world from a camera on the robot; a camera
        on a link (CameraMount.link) is placed by the joints' angles `joints_rad`."""
        width, height = size_px
        mount = mount or DEFAULT_MOUNT
        fx, fy = focal_px
        cx, cy = centre_px if centre_px is not None else (width / 2.0, height / 2.0)
        link = self.link_transform(mount, joints_rad)
        rotation = camera_rotation(pose, mount, link)
        origin = camera_position(pose, mount, link)
        image = np.empty((height, width, 3), np.uint8)
        image[:] = SKY_BGR
        self._floor(image, rotation, origin, (fx, fy, cx, cy))
        self._grid_lines(image, rotation, origin, (fx, fy, cx, cy))
        self._obstacles(image, rotation, origin, (fx, fy, cx, cy))
        return image

    def link_transform(
        self, mount: CameraMount | None, joints_rad: Mapping[str, float] | None
    ) -> Matrix | None:
        """base_link -> the mount's link, or None for a camera on the chassis."""
        if mount is None or mount.link is None or self.links is None:
            return None
        return self.links.transform(mount.link, joints_rad or {})

    def _project(
        self, camera_points: Matrix, intrinsics: tuple[float, float, float, float]
    ) -> Matrix:
        fx, fy, cx, cy = intrinsics
        z = camera_points[:, 2]
        return np.stack([fx * camera_points[:, 0] / z + cx, fy * camera_points[:, 1] / z + cy], -1)

    def _floor(
        self,
        image: Image,
        rotation: Matrix,
        origin: Matrix,
        intrinsics: tuple[float, float, float, float],
    ) -> None:
        # The floor as one big square around the camera, clipped and filled.
        reach = FLOOR_REACH_M * 4
        x, y = origin[0], origin[1]
        square = np.array(
            [
                [x - reach, y - reach, 0.0],
                [x + reach, y - reach, 0.0],
                [x + reach, y + reach, 0.0],
                [x - reach, y + reach, 0.0],
            ]
        )
        self._fill(image, square, rotation, origin, intrinsics, colour=FLOOR_BGR, outline=False)

    def _grid_lines(
        self,
        image: Image,
        rotation: Matrix,
        origin: Matrix,
        intrinsics: tuple[float, float, float, float],
    ) -> None:
        ends = (self._grid - origin) @ rotation.T  # (L, 2, 3)
        height, width = image.shape[:2]
        thickness = max(1, width // 400)
        for (start, end), world in zip(ends, self._grid, strict=True):
            if start[2] < NEAR_M and end[2] < NEAR_M:
                continue
            a, b = start, end
            if a[2] < NEAR_M:
                a = a + (NEAR_M - a[2]) / (b[2] - a[2]) * (b - a)
            elif b[2] < NEAR_M:
                b = b + (NEAR_M - b[2]) / (a[2] - b[2]) * (a - b)
            projected = self._project(np.array([a, b]), intrinsics)
            if not np.isfinite(projected).all():
                continue
            # Lines on whole metres are drawn darker.
            coordinate = world[0][0] if world[0][0] == world[1][0] else world[0][1]
            major = abs(coordinate - round(coordinate)) < 1e-6
            points = np.round(np.clip(projected, -1e6, 1e6) * (1 << SUBPIXEL_BITS)).astype(np.int64)
            colour = GRID_MAJOR_BGR if major else GRID_BGR
            cv2.line(
                image,
                (int(points[0, 0]), int(points[0, 1])),
                (int(points[1, 0]), int(points[1, 1])),
                colour,
                thickness,
                cv2.LINE_AA,
                SUBPIXEL_BITS,
            )
        del height

    def _obstacles(
        self,
        image: Image,
        rotation: Matrix,
        origin: Matrix,
        intrinsics: tuple[float, float, float, float],
    ) -> None:
        visible = []
        for quad, normal, colour in self._faces:
            centre = quad.mean(axis=0)
            # Back faces look away from the camera.
            if float(np.dot(normal, origin - centre)) <= 0.0:
                continue
            depth = float(np.linalg.norm(centre - origin))
            visible.append((depth, quad, normal, colour))
        visible.sort(key=lambda item: -item[0])
        for _depth, quad, normal, colour in visible:
            light = 0.55 + 0.45 * max(float(np.dot(normal, LIGHT)), 0.0)
            shaded = tuple(int(min(255, c * light)) for c in colour)
            self._fill(image, quad, rotation, origin, intrinsics, colour=shaded, outline=True)

    def _fill(
        self,
        image: Image,
        polygon: Matrix,
        rotation: Matrix,
        origin: Matrix,
        intrinsics: tuple[float, float, float, float],
        *,
        colour: tuple[int, ...],
        outline: bool,
    ) -> None:
        clipped = _clip_polygon((polygon - origin) @ rotation.T)
        if len(clipped) < 3:
            return
        projected = self._project(clipped, intrinsics)
        points = np.round(np.clip(projected, -1e6, 1e6) * (1 << SUBPIXEL_BITS)).astype(np.int32)
        cv2.fillPoly(image, [points], colour, cv2.LINE_AA, SUBPIXEL_BITS)
        if outline:
            cv2.polylines(image, [points], True, EDGE_BGR, 1, cv2.LINE_AA, SUBPIXEL_BITS)
