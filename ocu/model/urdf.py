"""Load a URDF robot description: links with their meshes and the joints between them.

Any URDF whose meshes trimesh can read works (STL, OBJ, PLY, GLB/GLTF, and DAE through
pycollada), so the real vendor model or another robot can replace the shipped low-poly
Engineer. Visual geometry is drawn; collision geometry is kept as primitives for the arm's
self-collision check (a collision mesh as the box around it), and drawn instead when no link
has a visual. Inertial elements are ignored.

A real robot's description is rarely perfect. What spoils only a part of it — a mesh that
cannot be found or read, a mimic of a joint that does not exist, degenerate geometry — is
skipped with a warning (`RobotModel.warnings`) and the rest loads. What other tools read and
means one thing only (numbers separated by commas, blank lines before `<?xml`, a vector with
an extra number, a spherical joint, a capsule) is read as they read it, with a warning naming
the line and the tool; what leaves no tree of links, or cannot be read at all, is an error.
A file that still holds xacro (`<xacro:...>`, `$(...)`, `${...}` left in its elements) gets a
hint to run xacro first.
"""

from __future__ import annotations

import dataclasses
import math
import re
import sys
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from xml.parsers import expat

import numpy as np
import trimesh

from ocu.model.mesh import MeshData, Rgba, empty_mesh, merge_meshes, mesh_from_trimesh
from ocu.model.mesh_files import (
    XACRO_HINT,
    MeshSkippedError,
    find_mesh_file,
    read_mesh_file,
)
from ocu.model.tree import JOINT_TYPES, Joint, KinematicTree, Matrix, Mimic, TreeError, transform
from ocu.profile import RobotProfile

# Joint types a display model draws fixed at their rest pose: urdfdom reads floating and
# planar (robot_state_publisher publishes no transform for them), pybullet reads spherical.
_AT_REST_TYPES = {
    "floating": "urdfdom reads it; robot_state_publisher publishes no motion for it",
    "planar": "urdfdom reads it; robot_state_publisher publishes no motion for it",
    "spherical": "pybullet reads it as a ball joint; urdfdom refuses it",
}
COLLISION_ONLY_NOTE = "no link has visual geometry: the collision geometry is drawn instead"
COLLISION_FALLBACK_NOTE = (
    "none of the visual geometry could be drawn: the collision geometry is drawn instead"
)
COLLISION_KINDS = ("box", "cylinder", "sphere")
# A number with a stray dot after it ("-1.57."): C's strtod/atof, used by urdfdom's and
# pybullet's readers, stop before the dot.
_TRAILING_DOT = re.compile(r"^([+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)\.$")
_XACRO_MARK = re.compile(r"\$\{[^}]*\}?|\$\([^)]*\)?")


@dataclass(frozen=True)
class CollisionShape:
    """A collision primitive in its link's frame: a box (size = extents), a cylinder along
    its z (size = radius, radius, length) or a sphere (size = radius x3). A URDF capsule
    (pybullet's extension) is kept as a cylinder of its radius and length: the collision
    check treats every cylinder as the capsule of that radius and length."""

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


def profile_urdf_path(profile: RobotProfile) -> Path:
    """The URDF of a profile's robot: its `urdf`, else the shipped Engineer model."""
    return profile.urdf if profile.urdf is not None else default_urdf_path()


def load_urdf(
    path: str | Path | None = None,
    *,
    meshes: bool = True,
    package_paths: Sequence[str | Path] = (),
) -> RobotModel:
    """Read a URDF file and every mesh it names; UrdfError with the reason on failure.

    Without `meshes` no visual mesh file is read (kinematics and collision shapes only).
    `package_paths` are extra folders searched for `package://` packages (before
    `OCU_PACKAGE_PATH`, `ROS_PACKAGE_PATH` and `AMENT_PREFIX_PATH`; see ocu.model.packages).
    """
    urdf_path = Path(path) if path is not None else default_urdf_path()
    try:
        text = urdf_path.read_text(encoding="utf-8-sig")
    except OSError as err:
        hint = f"; {XACRO_HINT}" if urdf_path.name.endswith(".xacro") else ""
        raise UrdfError(f"cannot read URDF {urdf_path}: {err.strerror}{hint}") from err
    except UnicodeDecodeError as err:
        raise UrdfError(f"{urdf_path}: not UTF-8 text: {err}") from err
    return parse_urdf(
        text,
        base_dir=urdf_path.parent,
        source=str(urdf_path),
        meshes=meshes,
        package_paths=package_paths,
    )


def looks_like_xacro(text: str, source: str = "") -> bool:
    """Whether a URDF still holds xacro markup outside its comments (or is named .xacro):
    a `<xacro:...>` element or a `${...}`/`$(...)` expression. Declaring the xacro namespace
    or mentioning xacro in a comment is not xacro left over."""
    if source.endswith(".xacro"):
        return True
    code = re.sub(r"<!--.*?-->", "", text, flags=re.DOTALL)
    return "<xacro:" in code or "${" in code or "$(" in code


def parse_urdf(
    text: str,
    base_dir: str | Path = ".",
    source: str = "<urdf>",
    *,
    meshes: bool = True,
    package_paths: Sequence[str | Path] = (),
) -> RobotModel:
    """Build a model from URDF text; relative mesh paths are resolved against base_dir."""
    warnings: list[str] = []
    text, first_line = _readable_text(text, source, warnings)
    try:
        root, lines = _parse_xml(text, first_line)
    except UrdfError as err:
        hint = f"; {XACRO_HINT}" if looks_like_xacro(text, source) else ""
        raise UrdfError(f"{source}: not valid XML: {err}{hint}") from None
    if root.tag != "robot":
        raise UrdfError(f"{source}: the root element is <{root.tag}>, not <robot>")
    reader = _Reader(source, Path(base_dir), lines=lines, package_paths=package_paths)
    reader.warnings.extend(warnings)
    leftovers = _xacro_leftovers(root, reader)
    reader.xacro = bool(leftovers) or source.endswith(".xacro")
    if leftovers:
        shown = "; ".join(leftovers[:3])
        more = f" (and {len(leftovers) - 3} more)" if len(leftovers) > 3 else ""
        reader.warnings.append(f"{source}: xacro left in the file: {shown}{more}; {XACRO_HINT}")
    materials = _named_materials(root, reader)
    link_elements = root.findall("link")
    if not link_elements:
        hint = f"; {XACRO_HINT}" if root.find("xacro:include") is not None else ""
        raise reader.fail(f"no <link> elements{hint}")
    link_names = [reader.required(element, "name", "<link>") for element in link_elements]
    joints = [reader.joint(element) for element in root.findall("joint")]
    joints = _drop_dangling_mimics(joints, reader)
    root_link = _root_link(source, link_names, joints)
    try:
        tree = KinematicTree(root_link, link_names, joints)
    except TreeError as err:
        raise reader.fail(str(err)) from err
    has_visuals = any(_has_geometry(element, "visual") for element in link_elements)
    has_collisions = any(_has_geometry(element, "collision") for element in link_elements)
    from_collision = has_collisions and not has_visuals
    if from_collision:
        reader.warnings.append(COLLISION_ONLY_NOTE)
    drawn = "collision" if from_collision else "visual"
    link_meshes = {
        name: reader.link_mesh(element, name, materials, drawn, read_files=meshes)
        for element, name in zip(link_elements, link_names, strict=True)
    }
    if meshes and has_collisions and not from_collision and not _any_triangles(link_meshes):
        # Visual geometry there is, but none of it could be drawn (missing meshes, say).
        from_collision = True
        reader.warnings.append(COLLISION_FALLBACK_NOTE)
        link_meshes = {
            name: reader.link_mesh(element, name, materials, "collision")
            for element, name in zip(link_elements, link_names, strict=True)
        }
    collisions = {
        name: shapes
        for element, name in zip(link_elements, link_names, strict=True)
        if (shapes := reader.collision_shapes(element, name))
    }
    return RobotModel(
        name=root.get("name", "robot"),
        tree=tree,
        meshes=link_meshes,
        source=source,
        collisions=collisions,
        warnings=tuple(reader.warnings),
        drawn_from_collision=from_collision,
    )


def _readable_text(text: str, source: str, warnings: list[str]) -> tuple[str, int]:
    """The text an XML parser can take, and the file line its first line is: a NUL byte ends
    the text (as for the C readers of urdfdom and pybullet, which stop there); whitespace
    before `<?xml` is dropped (TinyXML, which both use, skips it)."""
    nul = text.find("\0")
    if nul >= 0:
        line = text.count("\n", 0, nul) + 1
        rest = text[nul:].strip("\0 \t\r\n")
        what = "NUL bytes" if not rest else f"a NUL byte and {len(text) - nul - 1} more characters"
        warnings.append(
            f"{source}: line {line}: {what} after the XML, ignored (urdfdom and pybullet "
            "read the file as text that ends at the first NUL)"
        )
        text = text[:nul]
    stripped = text.lstrip()
    first_line = 1
    if stripped.startswith("<?xml") and stripped != text:
        first_line = text.count("\n", 0, len(text) - len(stripped)) + 1
        warnings.append(
            f"{source}: line {first_line}: the <?xml ...?> declaration is not at the start "
            "of the file (blank lines before it), read anyway (TinyXML, used by urdfdom and "
            "pybullet, skips them)"
        )
        text = stripped
    return text, first_line


def _parse_xml(text: str, first_line: int = 1) -> tuple[ET.Element, dict[int, int]]:
    """Elements (prefixes kept as written, e.g. `xacro:macro`; comments dropped) and the file
    line of each (by id of the element)."""
    builder = ET.TreeBuilder()
    parser = expat.ParserCreate()
    lines: dict[int, int] = {}

    def start(tag: str, attributes: dict[str, str]) -> None:
        element = builder.start(tag, attributes)
        lines[id(element)] = parser.CurrentLineNumber + first_line - 1

    parser.StartElementHandler = start
    parser.EndElementHandler = builder.end
    parser.CharacterDataHandler = builder.data
    parser.ordered_attributes = False
    try:
        parser.Parse(text, True)
        root = builder.close()
    except expat.ExpatError as err:
        line = (err.lineno or 1) + first_line - 1
        raise UrdfError(f"{expat.ErrorString(err.code)}: line {line}, column {err.offset}") from err
    except AssertionError as err:  # TreeBuilder: no element at all
        raise UrdfError("no element") from err
    return root, lines


def _xacro_leftovers(root: ET.Element, reader: _Reader) -> list[str]:
    """Where xacro markup is left: `<xacro:...>` elements and `${...}`/`$(...)` in
    attributes or text, each with its line."""
    found: list[str] = []
    for element in root.iter():
        line = reader.line_of(element)
        if element.tag.startswith("xacro:"):
            found.append(f"line {line}: <{element.tag}>")
            continue
        for name, value in element.attrib.items():
            mark = _XACRO_MARK.search(value)
            if mark:
                found.append(f"line {line}: {mark.group(0)} in {name}=")
        mark = _XACRO_MARK.search(element.text or "")
        if mark:
            found.append(f"line {line}: {mark.group(0)} in <{element.tag}>")
    return found


def _any_triangles(meshes: Mapping[str, MeshData]) -> bool:
    return any(mesh.triangle_count for mesh in meshes.values())


def _has_geometry(link: ET.Element, kind: str) -> bool:
    return any(
        (geometry := element.find("geometry")) is not None and len(geometry) > 0
        for element in link.findall(kind)
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


class _Reader:
    """Element parsers whose errors and warnings name the file, the element and its line."""

    def __init__(
        self,
        source: str,
        base_dir: Path,
        *,
        xacro: bool = False,
        lines: Mapping[int, int] | None = None,
        package_paths: Sequence[str | Path] = (),
    ) -> None:
        self.source = source
        self.base_dir = base_dir
        self.xacro = xacro
        self.lines = lines or {}
        self.package_paths = tuple(package_paths)
        self.warnings: list[str] = []

    def line_of(self, element: ET.Element) -> int | None:
        return self.lines.get(id(element))

    def _at(self, element: ET.Element | None) -> str:
        line = self.line_of(element) if element is not None else None
        return f"line {line}: " if line is not None else ""

    def fail(self, message: str, element: ET.Element | None = None) -> UrdfError:
        hint = f"; {XACRO_HINT}" if self.xacro else ""
        return UrdfError(f"{self.source}: {self._at(element)}{message}{hint}")

    def warn(self, message: str, element: ET.Element | None = None) -> None:
        self.warnings.append(f"{self.source}: {self._at(element)}{message}")

    def required(self, element: ET.Element, attribute: str, where: str) -> str:
        value = element.get(attribute)
        if not value:
            raise self.fail(f"{where} without a {attribute!r} attribute", element)
        return value

    def floats(
        self,
        element: ET.Element | None,
        attribute: str,
        count: int,
        where: str,
        default: float = 0.0,
    ) -> list[float]:
        """`count` numbers from an attribute (absent: the default). Read as urdfdom and
        pybullet read them, with a warning, when unambiguous: commas between the numbers,
        a stray dot after one ("-1.57."), and extra numbers after the first three of a
        vector (pybullet takes the first three)."""
        text = element.get(attribute) if element is not None else None
        if text is None:
            return [default] * count
        fixes: list[str] = []
        pieces = text.split()
        if "," in text:
            pieces = [p for p in re.split(r"[\s,]+", text.strip()) if p]
            fixes.append("commas between the numbers (pybullet reads it)")
        values: list[float] = []
        for piece in pieces:
            try:
                values.append(float(piece))
                continue
            except ValueError:
                pass
            dotted = _TRAILING_DOT.match(piece)
            if dotted is None:
                raise self.fail(
                    f"{where} {attribute}: {text!r} is not {count} numbers", element
                ) from None
            values.append(float(dotted.group(1)))
            fixes.append(
                f"{piece!r} read as {dotted.group(1)} (urdfdom and pybullet stop at the second dot)"
            )
        if len(values) > count == 3:
            fixes.append(
                f"{len(values)} numbers where 3 belong, the first three used (as pybullet does)"
            )
            values = values[:3]
        if len(values) != count or not all(math.isfinite(v) for v in values):
            raise self.fail(f"{where} {attribute}: {text!r} is not {count} finite numbers", element)
        if fixes:
            self.warn(f"{where} {attribute}={text!r}: {'; '.join(fixes)}", element)
        return values

    def origin(self, parent: ET.Element, where: str) -> Matrix:
        element = parent.find("origin")
        if element is None:
            return np.eye(4)
        xyz = self.floats(element, "xyz", 3, f"{where} origin")
        rpy = self.floats(element, "rpy", 3, f"{where} origin")
        return transform(xyz, rpy)

    def joint(self, element: ET.Element) -> Joint:
        name = self.required(element, "name", "<joint>")
        where = f"joint {name!r}"
        kind = self.required(element, "type", where)
        if kind in _AT_REST_TYPES:
            self.warn(
                f"{where}: a {kind} joint ({_AT_REST_TYPES[kind]}) is drawn fixed at its rest pose",
                element,
            )
            kind = "fixed"
        if kind not in JOINT_TYPES:
            raise self.fail(
                f"{where}: unknown joint type {kind!r} (expected one of "
                f"{', '.join((*JOINT_TYPES, *_AT_REST_TYPES))})",
                element,
            )
        links = []
        for tag in ("parent", "child"):
            link_element = element.find(tag)
            if link_element is None:
                raise self.fail(f"{where}: no <{tag}> element", element)
            links.append(self.required(link_element, "link", f"{where} <{tag}>"))
        axis_element = element.find("axis")
        axis = [1.0, 0.0, 0.0]
        if axis_element is not None and axis_element.get("xyz") is not None:
            axis = self.floats(axis_element, "xyz", 3, f"{where} axis")
        limits = self.limits(element, kind, where)
        mimic: Mimic | None = None
        mimic_element = element.find("mimic")
        if mimic_element is not None:
            mimic = Mimic(
                joint=self.required(mimic_element, "joint", f"{where} <mimic>"),
                multiplier=self.floats(
                    mimic_element, "multiplier", 1, f"{where} mimic", default=1.0
                )[0],
                offset=self.floats(mimic_element, "offset", 1, f"{where} mimic")[0],
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
            raise self.fail(str(err), element) from err

    def limits(self, element: ET.Element, kind: str, where: str) -> tuple[float, float] | None:
        """A revolute or prismatic joint's (lower, upper); None (no limits) where pybullet
        reads none: no <limit>, or lower above upper."""
        if kind not in ("revolute", "prismatic"):
            return None
        limit_element = element.find("limit")
        if limit_element is None:
            self.warn(
                f"{where}: a {kind} joint without <limit> moves without limits (pybullet "
                "reads it so; urdfdom refuses it)",
                element,
            )
            return None
        lower = self.floats(limit_element, "lower", 1, f"{where} limit")[0]
        upper = self.floats(limit_element, "upper", 1, f"{where} limit")[0]
        if lower > upper:
            self.warn(
                f"{where}: limit lower={lower:g} is above upper={upper:g}: read as no limits "
                "(as pybullet does)",
                limit_element,
            )
            return None
        return (lower, upper)

    def material_color(self, element: ET.Element, known: Mapping[str, Rgba]) -> Rgba | None:
        color_element = element.find("color")
        if color_element is not None:
            rgba = self.floats(color_element, "rgba", 4, "material color")
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
        found or read, or geometry that cannot be drawn, is left out with a warning."""
        parts: list[MeshData] = []
        for index, visual in enumerate(element.findall(drawn)):
            where = f"link {link!r} {drawn} {index}"
            material = visual.find("material")
            color = self.material_color(material, materials) if material is not None else None
            origin = self.origin(visual, where)
            geometry = visual.find("geometry")
            if geometry is None or len(geometry) == 0:
                self.warn(f"{where}: no <geometry>; nothing drawn for it", visual)
                continue
            if geometry[0].tag == "mesh" and not read_files:
                continue
            try:
                placed = self.geometry(geometry[0], where)
            except MeshSkippedError as err:
                self.warn(f"{err}; the rest of the robot is drawn", geometry[0])
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
                self.warn(f"{where}: no <geometry>; no collision shape for it", collision)
                continue
            shape = geometry[0]
            try:
                size = self.primitive_size(shape, where)
            except MeshSkippedError as err:
                self.warn(f"{err}; no collision shape for it", shape)
                continue
            if size is not None:
                kind = "cylinder" if shape.tag == "capsule" else shape.tag
                shapes.append(CollisionShape(kind, origin, size))
            elif shape.tag == "mesh":
                try:
                    placed = self.geometry(shape, where)
                except MeshSkippedError as err:
                    self.warn(f"{err}; no collision shape for it", shape)
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
        return tuple(shapes)

    def primitive_size(self, element: ET.Element, where: str) -> tuple[float, float, float] | None:
        """A primitive's size as CollisionShape keeps it; None for a mesh. Degenerate sizes
        (zero or negative) and shapes that cannot be drawn raise MeshSkippedError."""
        tag = element.tag
        if tag == "box":
            size = self.floats(element, "size", 3, f"{where} box")
            result = (size[0], size[1], size[2])
        elif tag in ("cylinder", "capsule"):
            radius = self.floats(element, "radius", 1, f"{where} {tag}")[0]
            length = self.floats(element, "length", 1, f"{where} {tag}")[0]
            result = (radius, radius, length)
        elif tag == "sphere":
            radius = self.floats(element, "radius", 1, f"{where} sphere")[0]
            result = (radius, radius, radius)
        elif tag == "mesh":
            return None
        elif tag == "plane":
            raise MeshSkippedError(f"{where}: <plane> (pybullet's infinite plane) is not drawn")
        else:
            raise MeshSkippedError(f"{where}: unknown geometry <{tag}>, left out")
        usable = result[0] > 0.0 and result[2] >= 0.0 if tag == "capsule" else min(result) > 0.0
        if not usable:
            raise MeshSkippedError(
                f"{where}: degenerate <{tag}> ({_describe_size(element)}): dropped"
            )
        return result

    def geometry(self, element: ET.Element, where: str) -> list[tuple[trimesh.Trimesh, Matrix]]:
        size = self.primitive_size(element, where)
        tag = element.tag
        if size is not None:
            if tag == "box":
                return [(trimesh.creation.box(extents=size), np.eye(4))]
            if tag == "cylinder":
                shape = trimesh.creation.cylinder(radius=size[0], height=size[2], sections=24)
                return [(shape, np.eye(4))]
            if tag == "capsule":
                shape = trimesh.creation.capsule(height=size[2], radius=size[0], count=(24, 12))
                return [(shape, np.eye(4))]
            return [(trimesh.creation.icosphere(subdivisions=2, radius=size[0]), np.eye(4))]
        filename = self.required(element, "filename", f"{where} <mesh>")
        scale = self.floats(element, "scale", 3, f"{where} mesh", default=1.0)
        if not all(abs(v) > 0.0 for v in scale):
            raise MeshSkippedError(f"{where}: mesh scale {element.get('scale')!r}: dropped")
        path = self.resolve(filename, where, element)
        scaling = np.diag([*scale, 1.0])
        return [(mesh, placement @ scaling) for mesh, placement in self.read_mesh(path, where)]

    def resolve(self, filename: str, where: str, element: ET.Element | None = None) -> Path:
        return find_mesh_file(
            filename,
            where,
            self.base_dir,
            self.package_paths,
            lambda message: self.warn(message, element),
        )

    def read_mesh(self, path: Path, where: str) -> list[tuple[trimesh.Trimesh, Matrix]]:
        return read_mesh_file(path, where, self.warn)


def _describe_size(element: ET.Element) -> str:
    return " ".join(f"{name}={value!r}" for name, value in element.attrib.items()) or "no size"
