"""Link geometry as flat-shaded triangle arrays, ready to be uploaded once to a GPU buffer."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import trimesh

Rgba = tuple[float, float, float, float]
DEFAULT_COLOR: Rgba = (0.7, 0.7, 0.72, 1.0)


@dataclass(frozen=True)
class MeshData:
    """Unindexed triangles in a link's frame: three vertices per triangle, one normal each."""

    positions: npt.NDArray[np.float32]  # (n, 3), metres
    normals: npt.NDArray[np.float32]  # (n, 3), unit length
    colors: npt.NDArray[np.uint8]  # (n, 4), RGBA

    @property
    def vertex_count(self) -> int:
        """Number of vertices (three per triangle)."""
        return int(self.positions.shape[0])

    @property
    def triangle_count(self) -> int:
        """Number of triangles."""
        return self.vertex_count // 3

    def bounds(self) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Lower and upper corner of the axis-aligned box around the vertices."""
        if self.vertex_count == 0:
            zero = np.zeros(3)
            return zero, zero
        return (
            self.positions.min(axis=0).astype(np.float64),
            self.positions.max(axis=0).astype(np.float64),
        )

    def center(self) -> npt.NDArray[np.float64]:
        """Centre of the bounding box in the link's frame."""
        low, high = self.bounds()
        result: npt.NDArray[np.float64] = (low + high) / 2.0
        return result


def empty_mesh() -> MeshData:
    """A mesh with no triangles (a link without visuals)."""
    return MeshData(
        positions=np.zeros((0, 3), dtype=np.float32),
        normals=np.zeros((0, 3), dtype=np.float32),
        colors=np.zeros((0, 4), dtype=np.uint8),
    )


def _rgba_bytes(color: Rgba) -> npt.NDArray[np.uint8]:
    return np.clip(np.round(np.asarray(color, dtype=np.float64) * 255.0), 0, 255).astype(np.uint8)


def _face_colors(mesh: trimesh.Trimesh, fallback: Rgba | None) -> npt.NDArray[np.uint8]:
    """One RGBA per face: the mesh's own colours if it has any, else the fallback."""
    faces = len(mesh.faces)
    visual: Any = mesh.visual
    if fallback is None:
        kind = getattr(visual, "kind", None)
        if kind == "face":
            own: npt.NDArray[np.uint8] = np.asarray(visual.face_colors, dtype=np.uint8)[:, :4]
            return own
        if kind == "vertex":
            per_vertex = np.asarray(visual.vertex_colors, dtype=np.uint16)[:, :4]
            averaged: npt.NDArray[np.uint8] = per_vertex[mesh.faces].mean(axis=1).astype(np.uint8)
            return averaged
        material = getattr(visual, "material", None)
        main = getattr(material, "main_color", None)
        if main is not None:
            return np.tile(np.asarray(main, dtype=np.uint8)[:4], (faces, 1))
        fallback = DEFAULT_COLOR
    return np.tile(_rgba_bytes(fallback), (faces, 1))


def mesh_from_trimesh(
    mesh: trimesh.Trimesh,
    transform: npt.NDArray[np.float64] | None = None,
    color: Rgba | None = None,
) -> MeshData:
    """Flat-shaded triangles of a trimesh, placed by a 4x4 transform.

    `color` overrides the mesh's own colours (a URDF material); without it the mesh's face or
    vertex colours are kept, or a neutral grey is used.
    """
    faces = np.asarray(mesh.faces, dtype=np.int64)
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    if transform is not None:
        vertices = vertices @ transform[:3, :3].T + transform[:3, 3]
    triangles = vertices[faces]  # (f, 3, 3)
    normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.divide(normals, length, out=np.zeros_like(normals), where=length > 0)
    colors = _face_colors(mesh, color)
    return MeshData(
        positions=triangles.reshape(-1, 3).astype(np.float32),
        normals=np.repeat(normals, 3, axis=0).astype(np.float32),
        colors=np.repeat(colors, 3, axis=0),
    )


def merge_meshes(meshes: Sequence[MeshData]) -> MeshData:
    """One mesh holding the triangles of several (one GPU buffer per link)."""
    if not meshes:
        return empty_mesh()
    if len(meshes) == 1:
        return meshes[0]
    return MeshData(
        positions=np.concatenate([m.positions for m in meshes]),
        normals=np.concatenate([m.normals for m in meshes]),
        colors=np.concatenate([m.colors for m in meshes]),
    )
