"""Collada (.dae) files read as RViz reads them, before trimesh/pycollada see them.

What RViz does (ros-visualization/rviz, src/rviz/mesh_loader.cpp): it loads meshes through
assimp, whose Collada loader puts two things on the scene's root node: the `<unit meter=..>`
scale and a rotation converting the file's `<up_axis>` to Y-up. `buildMesh()` skips the root
node's transform ("Don't convert to y-up orientation, which is what the root node in Assimp
does"), so `<up_axis>` is ignored, and `getMeshUnitRescale()` reads `<unit meter=..>` itself
and scales the vertices by it. Gazebo (gazebo-classic, gazebo/common/ColladaLoader.cc) does
the same: `Load()` reads `<unit meter=..>` and scales the mesh; `<up_axis>` is never read.
A description made for ROS therefore looks right with `<up_axis>` ignored and `<unit>`
applied, whatever its files declare (rviz issue #1045 and the packages that removed their
`up_axis` tags for tools that honour it). This module does the same: `ColladaFile.scale`
is the unit; the up axis is reported but not applied.

pycollada drops a whole `<node>` (geometry and all) when its material's texture names an
image that is not in the file. Such textures are removed here first, so the geometry loads
without them, and the caller says so.
"""

from __future__ import annotations

import contextlib
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field


@dataclass
class ColladaFile:
    """A .dae file prepared for pycollada."""

    data: bytes
    scale: float = 1.0  # <unit meter=..>: metres per file unit
    up_axis: str = "Y_UP"  # as declared (Collada's default is Y_UP); not applied
    declared_triangles: int = 0  # triangles the file's primitives declare (count attributes)
    notes: list[str] = field(default_factory=list)


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def prepare_collada(data: bytes) -> ColladaFile:
    """Read the unit and up axis, count the declared triangles, and strip textures that name
    a missing image. A file that is not XML is passed on untouched (pycollada reports it)."""
    try:
        root = ET.fromstring(data)
    except ET.ParseError:
        return ColladaFile(data)
    prepared = ColladaFile(data)
    for element in root.iter():
        tag = _local(element.tag)
        if tag == "unit" and element.get("meter"):
            try:
                meter = float(element.get("meter", "1"))
            except ValueError:
                meter = math.nan
            if 0.0 < meter < math.inf:
                prepared.scale = meter
            else:
                prepared.notes.append(f"unit meter={element.get('meter')!r} ignored")
        elif tag == "up_axis" and element.text:
            prepared.up_axis = element.text.strip()
        elif tag in ("triangles", "polylist", "polygons", "tristrips", "trifans"):
            with contextlib.suppress(ValueError):
                prepared.declared_triangles += int(element.get("count", "0"))
    broken = _broken_texture_images(root)
    if broken:
        _strip_textures(root)
        prepared.data = ET.tostring(root, encoding="utf-8")
        names = ", ".join(repr(name) for name in sorted(broken))
        prepared.notes.append(
            f"its texture names image {names}, which the file does not hold: the geometry "
            "is drawn without the texture"
        )
    return prepared


def _broken_texture_images(root: ET.Element) -> set[str]:
    """Image ids that a `<surface><init_from>` names but no `<image id=..>` holds."""
    images = {e.get("id") for e in root.iter() if _local(e.tag) == "image"}
    broken: set[str] = set()
    for surface in (e for e in root.iter() if _local(e.tag) == "surface"):
        for init in (e for e in surface if _local(e.tag) == "init_from"):
            name = (init.text or "").strip()
            if name and name not in images:
                broken.add(name)
    return broken


def _strip_textures(root: ET.Element) -> None:
    """Remove every texture use (a `<texture>` in a colour slot becomes white) and the
    surface and sampler parameters that feed them."""
    for parent in root.iter():
        for child in list(parent):
            tag = _local(child.tag)
            if tag == "texture":
                index = list(parent).index(child)
                parent.remove(child)
                namespace = child.tag[: -len("texture")]
                color = ET.Element(f"{namespace}color")
                color.text = "1 1 1 1"
                parent.insert(index, color)
            elif tag == "newparam" and any(
                _local(grandchild.tag) in ("surface", "sampler2D") for grandchild in child
            ):
                parent.remove(child)
