"""Small Collada files written for the tests: a box in any up axis and unit, with a texture
whose image is missing if asked (the cases of RViz's up_axis handling and anymal's foot)."""

from __future__ import annotations

import numpy as np
import trimesh


def collada_box(
    extents: tuple[float, float, float] = (0.1, 0.1, 0.3),
    *,
    up_axis: str | None = "Z_UP",
    unit_m: float = 1.0,
    broken_texture: bool = False,
    offset: tuple[float, float, float] = (0.0, 0.0, 0.15),
) -> str:
    """A .dae of a box (its corners in file units, shifted by `offset`) in one node."""
    box = trimesh.creation.box(extents=extents)
    vertices = np.asarray(box.vertices) + np.asarray(offset)
    positions = " ".join(f"{v:g}" for v in vertices.ravel())
    indices = " ".join(str(i) for i in np.asarray(box.faces).ravel())
    up = f"<up_axis>{up_axis}</up_axis>" if up_axis else ""
    if broken_texture:
        # The surface names an image id that <library_images> does not hold: pycollada
        # drops the whole node over it.
        effect = (
            '<newparam sid="surface"><surface type="2D"><init_from>foot_png</init_from>'
            "</surface></newparam>"
            '<newparam sid="sampler"><sampler2D><source>surface</source></sampler2D></newparam>'
            '<technique sid="common"><phong><diffuse><texture texture="sampler" '
            'texcoord="UVMap"/></diffuse></phong></technique>'
        )
    else:
        effect = (
            '<technique sid="common"><phong><diffuse><color>0.8 0.3 0.2 1</color></diffuse>'
            "</phong></technique>"
        )
    return f"""<?xml version="1.0" encoding="utf-8"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset><unit meter="{unit_m:g}" name="unit"/>{up}</asset>
  <library_effects><effect id="effect"><profile_COMMON>{effect}</profile_COMMON></effect>
  </library_effects>
  <library_materials><material id="material"><instance_effect url="#effect"/></material>
  </library_materials>
  <library_geometries><geometry id="box"><mesh>
    <source id="positions">
      <float_array id="positions-array" count="{vertices.size}">{positions}</float_array>
      <technique_common><accessor source="#positions-array" count="{len(vertices)}" stride="3">
        <param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/>
      </accessor></technique_common></source>
    <vertices id="vertices"><input semantic="POSITION" source="#positions"/></vertices>
    <triangles material="skin" count="{len(box.faces)}">
      <input semantic="VERTEX" source="#vertices" offset="0"/><p>{indices}</p></triangles>
  </mesh></geometry></library_geometries>
  <library_visual_scenes><visual_scene id="scene"><node id="part" name="part">
    <instance_geometry url="#box"><bind_material><technique_common>
      <instance_material symbol="skin" target="#material"/>
    </technique_common></bind_material></instance_geometry>
  </node></visual_scene></library_visual_scenes>
  <scene><instance_visual_scene url="#scene"/></scene>
</COLLADA>
"""
