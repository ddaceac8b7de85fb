"""Load a URDF robot description: links with their meshes and the joints between them.

Any URDF whose meshes trimesh can read works (STL, OBJ, PLY, GLB/GLTF, and DAE through
pycollada), so the real vendor model or another robot can replace the shipped low-poly
Engineer. Visual geometry is drawn; collision geometry is kept as primitives for the arm's
self-collision check (a collision mesh as the box around it), and drawn instead when no link
has a visual. Inertial elements are ignored.

A real robot's description is rarely perfect. What spoils only a part of it — a mesh that
cannot be found or read, a mimic of a joint that does not exist — is skipped with a warning
(`RobotModel.warnings`) and the rest loads; what leaves no tree of links is an error. A file
that still holds xacro (`.xacro`, `$(find ...)`, `${...}`) gets a hint to run xacro first.
"""

from __future__ import annotations

import dataclasses
import math
import os
import sys
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

from ocu.model.mesh import MeshData, Rgba, empty_mesh, merge_meshes, mesh_from_trimesh
from ocu.model.tree import JOINT_TYPES, Joint, KinematicTree, Matrix, Mimic, TreeError, transform

_UNSUPPORTED_TYPES = ("floating", "planar")
XACRO_HINT = (
    "this looks like an unprocessed xacro file: expand it first, e.g. "
    "`xacro robot.urdf.xacro > robot.urdf` (ROS's xacro package)"
)
COLLISION_ONLY_NOTE = "no link has visual geometry: the collision geometry is drawn instead"
COLLISION_KINDS = ("box", "cylinder", "sphere")


@dataclass(frozen=True)
class CollisionShape:
    """A collision primitive in its link's frame: a box (size = extents), a cylinder along
    its z (size = radius, radius, length) or a sphere (size = radius x3)."""

    kind: str
    origin: Matrix
    size: tuple[float, float, float]


class UrdfError(ValueError):
    """The URDF cannot be read or does not describe one tree of links."""


@dataclass(frozen=True)
class RobotModel:
    """A robot ready to draw: its kinematic tree and one mesh per link (in the link frame)."""

    name: str
    tree: KinematicTree
    meshes: Mapping[str, MeshData]
    source: str = "<urdf>"
    collisions: Mapping[str, tuple[CollisionShape, ...]] = field(default_factory=dict)
    # What was skipped while loading (a mesh, a mimic), and notes such as COLLISION_ONLY_NOTE.
    warnings: tuple[str, ...] = ()
    # Whether `meshes` hold the collision geometry (the URDF has no visual geometry).
    drawn_from_collision: bool = False

    @property
    def vertex_count(self) -> int:
        """Vertices over all links (three per triangle)."""
        return sum(mesh.vertex_count for mesh in self.meshes.values())

    @property
    def triangle_count(self) -> int:
        """Triangles over all links."""
        return sum(mesh.triangle_count for mesh in self.meshes.values())


def default_urdf_path() -> Path:
    """The low-poly Engineer model: the checkout's assets folder, else the installed copy."""
    in_checkout = Path(__file__).resolve().parents[2] / "assets" / "engineer.urdf"
    if in_checkout.exists():
        return in_checkout
    return Path(sys.prefix) / "share" / "ocu" / "assets" / "engineer.urdf"


def load_urdf(path: str | Path | None = None, *, meshes: bool = True) -> RobotModel:
    """Read a URDF file and every mesh it names; UrdfError with the reason on failure.

    Without `meshes` no visual mesh file is read (kinematics and collision shapes only).
    """
    urdf_path = Path(path) if path is not None else default_urdf_path()
    try:
        text = urdf_path.read_text(encoding="utf-8")
    except OSError as err:
        hint = f"; {XACRO_HINT}" if urdf_path.name.endswith(".xacro") else ""
        raise UrdfError(f"cannot read URDF {urdf_path}: {err.strerror}{hint}") from err
    except UnicodeDecodeError as err:
        raise UrdfError(f"{urdf_path}: not UTF-8 text: {err}") from err
    return parse_urdf(text, base_dir=urdf_path.parent, source=str(urdf_path), meshes=meshes)


def looks_like_xacro(text: str, source: str = "") -> bool:
    """Whether a URDF still holds xacro markup (or is named .xacro)."""
    return (
        source.endswith(".xacro")
        or "xmlns:xacro" in text
        or "<xacro:" in text
        or "$(" in text
        or "${" in text
    )


def parse_urdf(
    text: str, base_dir: str | Path = ".", source: str = "<urdf>", *, meshes: bool = True
) -> RobotModel:
    """Build a model from URDF text; relative mesh paths are resolved against base_dir."""
    xacro = looks_like_xacro(text, source)
    try:
        root = ET.fromstring(text)
    except ET.ParseError as err:
        hint = f"; {XACRO_HINT}" if xacro else ""
        raise UrdfError(f"{source}: not valid XML: {err}{hint}") from err
    if root.tag != "robot":
        raise UrdfError(f"{source}: the root element is <{root.tag}>, not <robot>")
    reader = _Reader(source, Path(base_dir), xacro=xacro)
    materials = _named_materials(root, reader)
    link_elements = root.findall("link")
    if not link_elements:
        raise reader.fail("no <link> elements")
    link_names = [reader.required(element, "name", "<link>") for element in link_elements]
    joints = [reader.joint(element) for element in root.findall("joint")]
    joints = _drop_dangling_mimics(joints, reader)
    root_link = _root_link(source, link_names, joints)
    try:
        tree = KinematicTree(root_link, link_names, joints)
    except TreeError as err:
        raise reader.fail(str(err)) from err
    has_visuals = any(element.find("visual") is not None for element in link_elements)
    has_collisions = any(element.find("collision") is not None for element in link_elements)
    from_collision = has_collisions and not has_visuals
    if from_collision:
        reader.warnings.append(COLLISION_ONLY_NOTE)
    drawn = "collision" if from_collision else "visual"
    link_meshes = {
        name: reader.link_mesh(element, name, materials, drawn, read_files=meshes)
        for element, name in zip(link_elements, link_names, strict=True)
    }
    collisions = {
        name: shapes
        for element, name in zip(link_elements, link_names, strict=True)
        if (shapes := reader.collision_shapes(element, name))
    }
    if xacro and not reader.warnings:
        reader.warnings.append(XACRO_HINT)
    return RobotModel(
        name=root.get("name", "robot"),
        tree=tree,
        meshes=link_meshes,
        source=source,
        collisions=collisions,
        warnings=tuple(reader.warnings),
        drawn_from_collision=from_collision,
    )


def _named_materials(root: ET.Element, reader: _Reader) -> dict[str, Rgba]:
    """Every material with a colour, by name: the robot's own first, then those defined in a
    link's visual (URDF lets a later visual reuse them by name alone)."""
    materials: dict[str, Rgba] = {}
    inner = [m for visual in root.iter("visual") for m in visual.findall("material")]
    for element in [*root.findall("material"), *inner]:
        name = element.get("name")
        if not name or name in materials:
            continue
        color = reader.material_color(element, {})
        if color is not None:
            materials[name] = color
    return materials


def _drop_dangling_mimics(joints: list[Joint], reader: _Reader) -> list[Joint]:
    """A mimic of a joint that is not a moving joint of the model: the joint moves on its own."""
    by_name = {joint.name: joint for joint in joints}
    kept = []
    for joint in joints:
        mimic = joint.mimic
        source = by_name.get(mimic.joint) if mimic is not None else None
        if mimic is not None and (source is None or source.type == "fixed" or source.mimic):
            reader.warnings.append(
                f"joint {joint.name!r} mimics {mimic.joint!r}, which is not a moving joint of "
                "this model: it moves on its own"
            )
            kept.append(dataclasses.replace(joint, mimic=None))
        else:
            kept.append(joint)
    return kept


def _root_link(source: str, links: list[str], joints: list[Joint]) -> str:
    children = {joint.child for joint in joints}
    roots = [name for name in links if name not in children]
    if len(roots) == 1:
        return roots[0]
    if not roots:
        cycle = _cycle_through_joints(joints)
        raise UrdfError(f"{source}: no root link; joints form a cycle: {' -> '.join(cycle)}")
    raise UrdfError(
        f"{source}: {len(roots)} links have no parent joint ({', '.join(roots)}); "
        "joints must connect all links into one tree"
    )


def _cycle_through_joints(joints: list[Joint]) -> list[str]:
    """Joint names around some cycle when every link has a parent (there must be one)."""
    parent_joint = {joint.child: joint for joint in joints}
    link = joints[0].child
    seen: dict[str, int] = {}
    path: list[str] = []
    while link not in seen and link in parent_joint:
        seen[link] = len(path)
        path.append(parent_joint[link].name)
        link = parent_joint[link].parent
    cycle = path[seen.get(link, 0) :]
    return [*cycle, cycle[0]] if cycle else path


class _MeshSkippedError(Exception):
    """A mesh file that cannot be found or read: its part of the robot is left out."""


class _Reader:
    """Element parsers whose errors name the file and the element."""

    def __init__(self, source: str, base_dir: Path, *, xacro: bool = False) -> None:
        self.source = source
        self.base_dir = base_dir
        self.xacro = xacro
        self.warnings: list[str] = []

    def fail(self, message: str) -> UrdfError:
        hint = f"; {XACRO_HINT}" if self.xacro else ""
        return UrdfError(f"{self.source}: {message}{hint}")

    def required(self, element: ET.Element, attribute: str, where: str) -> str:
        value = element.get(attribute)
        if not value:
            raise self.fail(f"{where} without a {attribute!r} attribute")
        return value

    def floats(self, text: str | None, count: int, where: str, default: float = 0.0) -> list[float]:
        if text is None:
            return [default] * count
        try:
            values = [float(v) for v in text.split()]
        except ValueError:
            raise self.fail(f"{where}: {text!r} is not {count} numbers") from None
        if len(values) != count or not all(math.isfinite(v) for v in values):
            raise self.fail(f"{where}: {text!r} is not {count} finite numbers")
        return values

    def origin(self, parent: ET.Element, where: str) -> Matrix:
        element = parent.find("origin")
        if element is None:
            return np.eye(4)
        xyz = self.floats(element.get("xyz"), 3, f"{where} origin xyz")
        rpy = self.floats(element.get("rpy"), 3, f"{where} origin rpy")
        return transform(xyz, rpy)

    def joint(self, element: ET.Element) -> Joint:
        name = self.required(element, "name", "<joint>")
        where = f"joint {name!r}"
        kind = self.required(element, "type", where)
        if kind in _UNSUPPORTED_TYPES:
            raise self.fail(
                f"{where}: joint type {kind!r} is not supported (a display model "
                f"needs one of {', '.join(JOINT_TYPES)})"
            )
        if kind not in JOINT_TYPES:
            raise self.fail(
                f"{where}: unknown joint type {kind!r} (expected one of {', '.join(JOINT_TYPES)})"
            )
        links = []
        for tag in ("parent", "child"):
            link_element = element.find(tag)
            if link_element is None:
                raise self.fail(f"{where}: no <{tag}> element")
            links.append(self.required(link_element, "link", f"{where} <{tag}>"))
        axis_element = element.find("axis")
        axis = [1.0, 0.0, 0.0]
        if axis_element is not None and axis_element.get("xyz") is not None:
            axis = self.floats(axis_element.get("xyz"), 3, f"{where} axis")
        limits: tuple[float, float] | None = None
        limit_element = element.find("limit")
        if kind in ("revolute", "prismatic"):
            if limit_element is None:
                raise self.fail(f"{where}: a {kind} joint needs a <limit lower=.. upper=..>")
            lower = self.floats(limit_element.get("lower"), 1, f"{where} limit lower")[0]
            upper = self.floats(limit_element.get("upper"), 1, f"{where} limit upper")[0]
            limits = (lower, upper)
        mimic: Mimic | None = None
        mimic_element = element.find("mimic")
        if mimic_element is not None:
            mimic = Mimic(
                joint=self.required(mimic_element, "joint", f"{where} <mimic>"),
                multiplier=self.floats(
                    mimic_element.get("multiplier"), 1, f"{where} mimic", default=1.0
                )[0],
                offset=self.floats(mimic_element.get("offset"), 1, f"{where} mimic")[0],
            )
        try:
            return Joint(
                name=name,
                type=kind,
                parent=links[0],
                child=links[1],
                origin=self.origin(element, where),
                axis=(axis[0], axis[1], axis[2]),
                limits=limits,
                mimic=mimic,
            )
        except TreeError as err:
            raise self.fail(str(err)) from err

    def material_color(self, element: ET.Element, known: Mapping[str, Rgba]) -> Rgba | None:
        color_element = element.find("color")
        if color_element is not None:
            rgba = self.floats(color_element.get("rgba"), 4, "material color rgba")
            return (rgba[0], rgba[1], rgba[2], rgba[3])
        name = element.get("name")
        return known.get(name) if name else None

    def link_mesh(
        self,
        element: ET.Element,
        link: str,
        materials: Mapping[str, Rgba],
        drawn: str = "visual",
        *,
        read_files: bool = True,
    ) -> MeshData:
        """The link's visual (or collision) geometry as one mesh; a mesh file that cannot be
        found or read is left out with a warning."""
        parts: list[MeshData] = []
        for index, visual in enumerate(element.findall(drawn)):
            where = f"link {link!r} {drawn} {index}"
            material = visual.find("material")
            color = self.material_color(material, materials) if material is not None else None
            origin = self.origin(visual, where)
            geometry = visual.find("geometry")
            if geometry is None or len(geometry) == 0:
                raise self.fail(f"{where}: no <geometry>")
            if geometry[0].tag == "mesh" and not read_files:
                continue
            try:
                placed = self.geometry(geometry[0], where)
            except _MeshSkippedError as err:
                self.warnings.append(f"{self.source}: {err}; the rest of the robot is drawn")
                continue
            for mesh, placement in placed:
                parts.append(mesh_from_trimesh(mesh, origin @ placement, color))
        return merge_meshes(parts) if parts else empty_mesh()

    def collision_shapes(self, element: ET.Element, link: str) -> tuple[CollisionShape, ...]:
        """The link's collision elements as primitives (a mesh as the box around it)."""
        shapes: list[CollisionShape] = []
        for index, collision in enumerate(element.findall("collision")):
            where = f"link {link!r} collision {index}"
            origin = self.origin(collision, where)
            geometry = collision.find("geometry")
            if geometry is None or len(geometry) == 0:
                raise self.fail(f"{where}: no <geometry>")
            shape = geometry[0]
            if shape.tag == "box":
                size = self.floats(shape.get("size"), 3, f"{where} box size")
                shapes.append(CollisionShape("box", origin, (size[0], size[1], size[2])))
            elif shape.tag == "cylinder":
                radius = self.floats(shape.get("radius"), 1, f"{where} cylinder radius")[0]
                length = self.floats(shape.get("length"), 1, f"{where} cylinder length")[0]
                shapes.append(CollisionShape("cylinder", origin, (radius, radius, length)))
            elif shape.tag == "sphere":
                radius = self.floats(shape.get("radius"), 1, f"{where} sphere radius")[0]
                shapes.append(CollisionShape("sphere", origin, (radius, radius, radius)))
            elif shape.tag == "mesh":
                try:
                    placed = self.geometry(shape, where)
                except _MeshSkippedError as err:
                    self.warnings.append(f"{self.source}: {err}; no collision shape for it")
                    continue
                points = np.vstack(
                    [
                        np.asarray(mesh.vertices) @ placement[:3, :3].T + placement[:3, 3]
                        for mesh, placement in placed
                    ]
                )
                low, high = points.min(axis=0), points.max(axis=0)
                center = np.eye(4)
                center[:3, 3] = (low + high) / 2.0
                extents = high - low
                shapes.append(
                    CollisionShape(
                        "box",
                        origin @ center,
                        (float(extents[0]), float(extents[1]), float(extents[2])),
                    )
                )
            else:
                raise self.fail(f"{where}: unknown geometry <{shape.tag}>")
        return tuple(shapes)

    def geometry(self, element: ET.Element, where: str) -> list[tuple[trimesh.Trimesh, Matrix]]:
        tag = element.tag
        if tag == "box":
            size = self.floats(element.get("size"), 3, f"{where} box size")
            return [(trimesh.creation.box(extents=size), np.eye(4))]
        if tag == "cylinder":
            radius = self.floats(element.get("radius"), 1, f"{where} cylinder radius")[0]
            length = self.floats(element.get("length"), 1, f"{where} cylinder length")[0]
            return [
                (trimesh.creation.cylinder(radius=radius, height=length, sections=24), np.eye(4))
            ]
        if tag == "sphere":
            radius = self.floats(element.get("radius"), 1, f"{where} sphere radius")[0]
            return [(trimesh.creation.icosphere(subdivisions=2, radius=radius), np.eye(4))]
        if tag == "mesh":
            filename = self.required(element, "filename", f"{where} <mesh>")
            scale = self.floats(element.get("scale"), 3, f"{where} mesh scale", default=1.0)
            path = self.resolve(filename, where)
            scaling = np.diag([*scale, 1.0])
            return [(mesh, placement @ scaling) for mesh, placement in self.read_mesh(path, where)]
        raise self.fail(f"{where}: unknown geometry <{tag}>")

    def resolve(self, filename: str, where: str) -> Path:
        candidates = _mesh_candidates(filename, self.base_dir)
        for candidate in candidates:
            if candidate.is_file():
                return candidate
        looked = ", ".join(str(c) for c in candidates)
        hint = f"; {XACRO_HINT}" if "$(" in filename or "${" in filename else ""
        raise _MeshSkippedError(
            f"{where}: mesh file not found: {filename} (looked in: {looked}){hint}"
        )

    def read_mesh(self, path: Path, where: str) -> list[tuple[trimesh.Trimesh, Matrix]]:
        try:
            loaded = trimesh.load(str(path))
        except Exception as err:  # trimesh raises many types for unreadable files
            hint = (
                " (reading .dae needs the pycollada package: pip install pycollada)"
                if path.suffix.lower() == ".dae" and "collada" in str(err).lower()
                else ""
            )
            raise _MeshSkippedError(f"{where}: cannot read mesh {path}: {err}{hint}") from err
        if isinstance(loaded, trimesh.Trimesh):
            meshes = [loaded]
        elif isinstance(loaded, trimesh.Scene):
            meshes = [g for g in loaded.dump() if isinstance(g, trimesh.Trimesh)]
        else:
            meshes = []
        meshes = [m for m in meshes if len(m.faces) > 0]
        if not meshes:
            raise _MeshSkippedError(f"{where}: mesh {path} holds no triangles")
        return [(mesh, np.eye(4)) for mesh in meshes]


def _mesh_candidates(filename: str, base_dir: Path) -> list[Path]:
    """Where a URDF mesh reference may point, most likely first."""
    if filename.startswith("file://"):
        return [Path(filename.removeprefix("file://"))]
    for scheme in ("package://", "model://"):
        if filename.startswith(scheme):
            package, _, rest = filename.removeprefix(scheme).partition("/")
            candidates: list[Path] = []
            if not package:
                # `package:///path`: no package name; the path is absolute, or relative to
                # the URDF's folder or one of its parents.
                rest = rest.lstrip("/")
                folders = (base_dir.resolve(), *base_dir.resolve().parents)
                candidates = [Path("/") / rest, *(folder / rest for folder in folders[:4])]
                return list(dict.fromkeys(candidates))
            folder_chain = (base_dir.resolve(), *base_dir.resolve().parents)
            for folder in folder_chain[:4]:
                if folder.name == package:
                    candidates.append(folder / rest)
                candidates.append(folder / package / rest)
            for entry in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep):
                if entry:
                    candidates.extend((Path(entry) / package / rest, Path(entry) / rest))
            candidates.append(base_dir / rest)
            return list(dict.fromkeys(candidates))
    path = Path(filename)
    return [path if path.is_absolute() else base_dir / path]
