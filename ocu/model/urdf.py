"""Load a URDF robot description: links with their meshes and the joints between them.

Any URDF whose meshes trimesh can read works (STL, OBJ, PLY, GLB/GLTF; DAE needs pycollada),
so the real vendor model or another robot can replace the shipped low-poly Engineer. Only
visual geometry is read; collision and inertial elements are ignored.
"""

from __future__ import annotations

import math
import os
import sys
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from ocu.model.mesh import MeshData, Rgba, empty_mesh, merge_meshes, mesh_from_trimesh
from ocu.model.tree import JOINT_TYPES, Joint, KinematicTree, Matrix, Mimic, TreeError, transform

_UNSUPPORTED_TYPES = ("floating", "planar")


class UrdfError(ValueError):
    """The URDF cannot be read or does not describe one tree of links."""


@dataclass(frozen=True)
class RobotModel:
    """A robot ready to draw: its kinematic tree and one mesh per link (in the link frame)."""

    name: str
    tree: KinematicTree
    meshes: Mapping[str, MeshData]
    source: str = "<urdf>"

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


def load_urdf(path: str | Path | None = None) -> RobotModel:
    """Read a URDF file and every mesh it names; UrdfError with the reason on failure."""
    urdf_path = Path(path) if path is not None else default_urdf_path()
    try:
        text = urdf_path.read_text(encoding="utf-8")
    except OSError as err:
        raise UrdfError(f"cannot read URDF {urdf_path}: {err.strerror}") from err
    return parse_urdf(text, base_dir=urdf_path.parent, source=str(urdf_path))


def parse_urdf(text: str, base_dir: str | Path = ".", source: str = "<urdf>") -> RobotModel:
    """Build a model from URDF text; relative mesh paths are resolved against base_dir."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as err:
        raise UrdfError(f"{source}: not valid XML: {err}") from err
    if root.tag != "robot":
        raise UrdfError(f"{source}: the root element is <{root.tag}>, not <robot>")
    reader = _Reader(source, Path(base_dir))
    materials = {
        name: color
        for element in root.findall("material")
        if (name := element.get("name")) and (color := reader.material_color(element, {}))
    }
    link_elements = root.findall("link")
    if not link_elements:
        raise UrdfError(f"{source}: no <link> elements")
    link_names = [reader.required(element, "name", "<link>") for element in link_elements]
    joints = [reader.joint(element) for element in root.findall("joint")]
    root_link = _root_link(source, link_names, joints)
    try:
        tree = KinematicTree(root_link, link_names, joints)
    except TreeError as err:
        raise UrdfError(f"{source}: {err}") from err
    meshes = {
        name: reader.link_mesh(element, name, materials)
        for element, name in zip(link_elements, link_names, strict=True)
    }
    return RobotModel(
        name=root.get("name", "robot"),
        tree=tree,
        meshes=meshes,
        source=source,
    )


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


class _Reader:
    """Element parsers whose errors name the file and the element."""

    def __init__(self, source: str, base_dir: Path) -> None:
        self.source = source
        self.base_dir = base_dir

    def fail(self, message: str) -> UrdfError:
        return UrdfError(f"{self.source}: {message}")

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

    def link_mesh(self, element: ET.Element, link: str, materials: Mapping[str, Rgba]) -> MeshData:
        parts: list[MeshData] = []
        for index, visual in enumerate(element.findall("visual")):
            where = f"link {link!r} visual {index}"
            material = visual.find("material")
            color = self.material_color(material, materials) if material is not None else None
            origin = self.origin(visual, where)
            geometry = visual.find("geometry")
            if geometry is None or len(geometry) == 0:
                raise self.fail(f"{where}: no <geometry>")
            for mesh, placement in self.geometry(geometry[0], where):
                parts.append(mesh_from_trimesh(mesh, origin @ placement, color))
        return merge_meshes(parts) if parts else empty_mesh()

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
        raise self.fail(f"{where}: mesh file not found: {filename} (looked in: {looked})")

    def read_mesh(self, path: Path, where: str) -> list[tuple[trimesh.Trimesh, Matrix]]:
        try:
            loaded = trimesh.load(str(path))
        except Exception as err:  # trimesh raises many types for unreadable files
            hint = (
                " (reading .dae needs the pycollada package)"
                if path.suffix.lower() == ".dae"
                else ""
            )
            raise self.fail(f"{where}: cannot read mesh {path}: {err}{hint}") from err
        if isinstance(loaded, trimesh.Trimesh):
            meshes = [loaded]
        elif isinstance(loaded, trimesh.Scene):
            meshes = [g for g in loaded.dump() if isinstance(g, trimesh.Trimesh)]
        else:
            meshes = []
        meshes = [m for m in meshes if len(m.faces) > 0]
        if not meshes:
            raise self.fail(f"{where}: mesh {path} holds no triangles")
        return [(mesh, np.eye(4)) for mesh in meshes]


def _mesh_candidates(filename: str, base_dir: Path) -> list[Path]:
    """Where a URDF mesh reference may point, most likely first."""
    if filename.startswith("file://"):
        return [Path(filename.removeprefix("file://"))]
    for scheme in ("package://", "model://"):
        if filename.startswith(scheme):
            package, _, rest = filename.removeprefix(scheme).partition("/")
            candidates: list[Path] = []
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
