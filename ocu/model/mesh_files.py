"""Finding and reading the mesh files a URDF names: package:// as ROS resolves it, paths
relative to a data folder's root as pybullet finds them, Collada through pycollada (its
up_axis ignored and its unit applied, as RViz does: ocu.model.collada), and the triangles that
cannot be drawn (NaN or infinite corners) dropped."""

from __future__ import annotations

import io
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import trimesh

from ocu.model.collada import prepare_collada
from ocu.model.packages import package_folders, package_roots
from ocu.model.tree import Matrix

XACRO_HINT = (
    "this looks like an unprocessed xacro file: expand it first, e.g. "
    "`xacro robot.urdf.xacro > robot.urdf` (ROS's xacro package)"
)


class MeshSkippedError(Exception):
    """A mesh file that cannot be found or read: its part of the robot is left out."""


def find_mesh_file(
    filename: str,
    where: str,
    base_dir: Path,
    package_paths: Sequence[str | Path],
    warn: Callable[[str], None],
) -> Path:
    """The file a URDF mesh reference names, as ROS (package://) or pybullet (a data folder's
    root) would find it; MeshSkippedError naming where it looked if none is there."""
    candidates = mesh_candidates(filename, base_dir, package_paths)
    for candidate in candidates:
        if candidate.is_file():
            return candidate
    # A path relative to a data folder's root rather than to the URDF (pybullet finds it
    # through setAdditionalSearchPath): look under the folders above the URDF.
    if not filename.startswith(("package://", "model://", "file://", "/")):
        roots = [Path(r) for r in package_roots(package_paths)]
        for folder in (*base_dir.resolve().parents, *roots):
            candidate = folder / filename
            if candidate.is_file():
                warn(
                    f"{where}: mesh {filename} is not next to the URDF; found as "
                    f"{candidate}, under {folder} (as pybullet finds it through its "
                    "additional search path)",
                )
                return candidate
    shown = [str(c) for c in candidates[:8]]
    if len(candidates) > 8:
        shown.append(f"and {len(candidates) - 8} more")
    hint = f"; {XACRO_HINT}" if "$(" in filename or "${" in filename else ""
    extra = (
        "; name the folder holding the package with --package-path or OCU_PACKAGE_PATH"
        if filename.startswith(("package://", "model://"))
        else ""
    )
    raise MeshSkippedError(
        f"{where}: mesh file not found: {filename} (looked in: {', '.join(shown)}){extra}{hint}"
    )


def read_mesh_file(
    path: Path, where: str, warn: Callable[[str], None]
) -> list[tuple[trimesh.Trimesh, Matrix]]:
    """The finite triangle meshes of a mesh file, each with its unit scaling (Collada's
    <unit>); MeshSkippedError when nothing can be drawn from it."""
    unit = np.eye(4)
    declared = 0
    try:
        if path.suffix.lower() == ".dae":
            prepared = prepare_collada(path.read_bytes())
            unit = np.diag([prepared.scale] * 3 + [1.0])
            declared = prepared.declared_triangles
            for note in prepared.notes:
                warn(f"{where}: mesh {path}: {note}")
            with warnings.catch_warnings():
                # pycollada 0.9.3 (the newest) reshapes its arrays by setting
                # ndarray.shape, which numpy 2.5 deprecates: harmless until numpy removes
                # it, and nothing this program can change. Only that warning from pycollada.
                warnings.filterwarnings(
                    "ignore",
                    message="Setting the shape on a NumPy array has been deprecated",
                    category=DeprecationWarning,
                    module=r"collada(\.|$)",
                )
                loaded = trimesh.load(io.BytesIO(prepared.data), file_type="dae")
        else:
            loaded = trimesh.load(str(path))
    except Exception as err:  # trimesh raises many types for unreadable files
        hint = (
            " (reading .dae needs the pycollada package: pip install pycollada)"
            if path.suffix.lower() == ".dae" and "collada" in str(err).lower()
            else ""
        )
        raise MeshSkippedError(f"{where}: cannot read mesh {path}: {err}{hint}") from err
    if isinstance(loaded, trimesh.Trimesh):
        meshes = [loaded]
    elif isinstance(loaded, trimesh.Scene):
        meshes = [g for g in loaded.dump() if isinstance(g, trimesh.Trimesh)]
    else:
        meshes = []
    meshes = [m for m in meshes if len(m.faces) > 0]
    if not meshes:
        if declared:
            raise MeshSkippedError(
                f"{where}: mesh {path} declares {declared} triangles, but pycollada "
                "could read none of them"
            )
        raise MeshSkippedError(f"{where}: mesh {path} holds no triangles")
    finite = [finite_part(mesh) for mesh in meshes]
    dropped = sum(len(m.faces) - len(f.faces) for m, f in zip(meshes, finite, strict=True))
    if dropped:
        warn(f"{where}: mesh {path}: {dropped} triangles with non-finite corners dropped")
    meshes = [m for m in finite if len(m.faces) > 0]
    if not meshes:
        raise MeshSkippedError(f"{where}: mesh {path} holds no finite triangles")
    return [(mesh, unit) for mesh in meshes]


def finite_part(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """The mesh without faces that touch a NaN or infinite vertex."""
    vertices = np.asarray(mesh.vertices)
    bad = ~np.isfinite(vertices).all(axis=1)
    if not bad.any():
        return mesh
    keep = ~bad[np.asarray(mesh.faces)].any(axis=1)
    part = mesh.copy()
    part.update_faces(keep)
    return part


def mesh_candidates(
    filename: str, base_dir: Path, package_paths: Sequence[str | Path] = ()
) -> list[Path]:
    """Where a URDF mesh reference may point, most likely first."""
    if filename.startswith("file://"):
        return [Path(filename.removeprefix("file://"))]
    for scheme in ("package://", "model://"):
        if filename.startswith(scheme):
            package, _, rest = filename.removeprefix(scheme).partition("/")
            folders = (base_dir.resolve(), *base_dir.resolve().parents)
            if not package:
                # `package:///path`: no package name; the path is absolute, or relative to
                # the URDF's folder or one of its parents.
                rest = rest.lstrip("/")
                return list(dict.fromkeys([Path("/") / rest, *(f / rest for f in folders)]))
            candidates = [f / rest for f in package_folders(package, base_dir, package_paths)]
            candidates.append(base_dir / rest)
            return list(dict.fromkeys(candidates))
    path = Path(filename)
    return [path if path.is_absolute() else base_dir / path]
