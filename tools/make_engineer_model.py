"""Build the low-poly Servosila Engineer model: assets/engineer.urdf and assets/meshes/*.stl.

No vendor model is available, so the robot is put together from primitives. Proportions are
approximate (read off photographs, not measured); joint names, limits and the track width
come from the robot profile, so the model and the OCU agree on every robot fact. Each mesh is
written in its link's frame, whose origin lies on the link's joint axis.

Run from the repository root; the output is byte-for-byte reproducible:

    .venv/bin/python tools/make_engineer_model.py [--out assets] [--profile PATH]
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import struct
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
import trimesh

from ocu.model.tree import axis_rotation
from ocu.profile import RobotProfile, load_profile

Array = npt.NDArray[np.float64]

# Dimensions in metres; x forward, y left, z up; the chassis frame sits on the ground.
WHEEL_RADIUS = 0.09
WHEEL_BASE = 0.54  # front to rear sprocket
TRACK_BELT_WIDTH = 0.10
HULL_LENGTH = 0.60
HULL_BOTTOM, HULL_TOP = 0.05, 0.21
FLIPPER_LENGTH = 0.30
FLIPPER_TIP_RADIUS = 0.05
FLIPPER_WIDTH = 0.06
WAIST_X = -0.12
SHOULDER_HEIGHT = 0.13  # above the turret base
UPPER_ARM_LENGTH = 0.42
FOREARM_LENGTH = 0.38
ROUND_SECTIONS = 20

# Neutral colours: saturated amber is kept for stale joints and light blue for the ghost.
COLORS = {
    "hull": (0.40, 0.45, 0.31, 1.0),
    "track": (0.12, 0.12, 0.13, 1.0),
    "flipper": (0.22, 0.22, 0.24, 1.0),
    "arm": (0.80, 0.80, 0.82, 1.0),
    "joint": (0.27, 0.28, 0.30, 1.0),
    "head": (0.30, 0.31, 0.34, 1.0),
    "lens": (0.05, 0.05, 0.07, 1.0),
    "gripper": (0.58, 0.60, 0.63, 1.0),
}


def box(size: Sequence[float], center: Sequence[float]) -> trimesh.Trimesh:
    """An axis-aligned box."""
    mesh: trimesh.Trimesh = trimesh.creation.box(extents=size)
    mesh.apply_translation(center)
    return mesh


def cylinder(
    radius: float, length: float, center: Sequence[float], axis: str, sections: int = 0
) -> trimesh.Trimesh:
    """A cylinder along x, y or z."""
    mesh: trimesh.Trimesh = trimesh.creation.cylinder(
        radius=radius, height=length, sections=sections or ROUND_SECTIONS
    )
    if axis == "x":
        mesh.apply_transform(axis_rotation((0.0, 1.0, 0.0), math.pi / 2))
    elif axis == "y":
        mesh.apply_transform(axis_rotation((1.0, 0.0, 0.0), math.pi / 2))
    mesh.apply_translation(center)
    return mesh


def rounded_outline(
    start: tuple[float, float], start_radius: float, end: tuple[float, float], end_radius: float
) -> Array:
    """Convex outline (x, z) around two circles: a stadium, tapered when the radii differ."""
    (x0, z0), (x1, z1) = start, end
    length = math.hypot(x1 - x0, z1 - z0)
    heading = math.atan2(z1 - z0, x1 - x0)
    # Angle of the tangent points off the centre line (outer tangents of two circles).
    spread = math.acos((start_radius - end_radius) / length)
    points = []
    for angle in np.linspace(-spread, spread, ROUND_SECTIONS // 2 + 1):
        a = heading + angle
        points.append((x1 + end_radius * math.cos(a), z1 + end_radius * math.sin(a)))
    for angle in np.linspace(spread, 2 * math.pi - spread, ROUND_SECTIONS // 2 + 1):
        a = heading + angle
        points.append((x0 + start_radius * math.cos(a), z0 + start_radius * math.sin(a)))
    return np.asarray(points)


def prism(outline_xz: Array, y_low: float, y_high: float) -> trimesh.Trimesh:
    """A convex (x, z) outline extruded along y between y_low and y_high."""
    count = len(outline_xz)
    low = np.column_stack([outline_xz[:, 0], np.full(count, y_low), outline_xz[:, 1]])
    high = np.column_stack([outline_xz[:, 0], np.full(count, y_high), outline_xz[:, 1]])
    vertices = np.vstack([low, high])
    faces: list[list[int]] = []
    for i in range(count):
        j = (i + 1) % count
        faces.extend(([i, j, count + j], [i, count + j, count + i]))
    for i in range(1, count - 1):
        faces.extend(([0, i + 1, i], [count, count + i, count + i + 1]))
    mesh = trimesh.Trimesh(vertices=vertices, faces=np.asarray(faces), process=False)
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def join(*parts: trimesh.Trimesh) -> trimesh.Trimesh:
    """One mesh from several (overlaps are fine for drawing)."""
    mesh = trimesh.util.concatenate(list(parts))
    assert isinstance(mesh, trimesh.Trimesh)
    return mesh


def hull_mesh() -> trimesh.Trimesh:
    """The chassis body between the tracks, with its top deck and bumpers."""
    height = HULL_TOP - HULL_BOTTOM
    inner_width = 0.40
    return join(
        box((HULL_LENGTH, inner_width, height), (0.0, 0.0, HULL_BOTTOM + height / 2)),
        box((0.50, 0.36, 0.03), (-0.02, 0.0, HULL_TOP + 0.015)),
        box((0.04, inner_width + 0.02, 0.06), (HULL_LENGTH / 2 + 0.01, 0.0, 0.12)),
        box((0.04, inner_width + 0.02, 0.06), (-HULL_LENGTH / 2 - 0.01, 0.0, 0.12)),
    )


def chassis_cameras_mesh() -> trimesh.Trimesh:
    """Front and rear driving cameras on the hull."""
    return join(
        box((0.04, 0.08, 0.05), (0.25, 0.0, HULL_TOP + 0.055)),
        cylinder(0.016, 0.02, (0.275, 0.0, HULL_TOP + 0.055), "x"),
        box((0.04, 0.08, 0.05), (-0.27, 0.0, HULL_TOP + 0.055)),
        cylinder(0.016, 0.02, (-0.295, 0.0, HULL_TOP + 0.055), "x"),
    )


def track_mesh() -> trimesh.Trimesh:
    """One track in its own frame (centred on the belt): belt, cleats and wheel hubs."""
    half = WHEEL_BASE / 2
    belt = prism(
        rounded_outline((-half, WHEEL_RADIUS), WHEEL_RADIUS, (half, WHEEL_RADIUS), WHEEL_RADIUS),
        -TRACK_BELT_WIDTH / 2,
        TRACK_BELT_WIDTH / 2,
    )
    parts = [belt]
    for x in np.arange(-half + 0.03, half, 0.06):
        parts.append(box((0.02, TRACK_BELT_WIDTH, 0.012), (x, 0.0, 2 * WHEEL_RADIUS + 0.004)))
        parts.append(box((0.02, TRACK_BELT_WIDTH, 0.012), (x, 0.0, -0.004)))
    for x in (-half, 0.0, half):
        parts.append(cylinder(0.05, TRACK_BELT_WIDTH + 0.01, (x, 0.0, WHEEL_RADIUS), "y"))
    return join(*parts)


def flipper_mesh() -> trimesh.Trimesh:
    """A tapered tracked flipper pointing forward from its axle, cleats on the rim."""
    outline = rounded_outline((0.0, 0.0), WHEEL_RADIUS, (FLIPPER_LENGTH, 0.0), FLIPPER_TIP_RADIUS)
    parts = [prism(outline, -FLIPPER_WIDTH / 2, FLIPPER_WIDTH / 2)]
    parts.append(cylinder(0.035, FLIPPER_WIDTH + 0.02, (0.0, 0.0, 0.0), "y"))
    return join(*parts)


def turret_mesh() -> trimesh.Trimesh:
    """The waist: a turntable with a yoke that carries the shoulder axis."""
    return join(
        cylinder(0.10, 0.04, (0.0, 0.0, 0.02), "z", sections=28),
        box((0.10, 0.03, SHOULDER_HEIGHT), (0.0, 0.065, SHOULDER_HEIGHT / 2 + 0.02)),
        box((0.10, 0.03, SHOULDER_HEIGHT), (0.0, -0.065, SHOULDER_HEIGHT / 2 + 0.02)),
        cylinder(0.045, 0.16, (0.0, 0.0, SHOULDER_HEIGHT), "y"),
    )


def segment_mesh(length: float, width: float, height: float) -> trimesh.Trimesh:
    """An arm segment from its proximal axis (origin) along +x, with joint hubs.

    The distal hub is thinner and wider than the next segment's proximal hub, so that the
    two never share a surface (which would flicker in the depth test).
    """
    return join(
        box((length, width, height), (length / 2, 0.0, 0.0)),
        cylinder(height * 0.75, width + 0.02, (0.0, 0.0, 0.0), "y"),
        cylinder(height * 0.6, width + 0.045, (length, 0.0, 0.0), "y"),
    )


def neck_mesh() -> trimesh.Trimesh:
    """The wrist housing between the forearm and the head and gripper."""
    return join(
        cylinder(0.042, 0.10, (0.0, 0.0, 0.0), "y"),
        box((0.08, 0.08, 0.11), (0.04, 0.0, -0.015)),
    )


def head_mesh() -> trimesh.Trimesh:
    """The camera head, origin on the pan axis."""
    return join(
        cylinder(0.04, 0.03, (0.0, 0.0, 0.015), "z"),
        box((0.13, 0.22, 0.10), (0.04, 0.0, 0.08)),
        box((0.06, 0.08, 0.02), (0.02, 0.0, 0.14)),
    )


def head_cameras_mesh() -> trimesh.Trimesh:
    """Stereo pair and zoom lens on the head's front face (head frame)."""
    front = 0.105 + 0.01
    return join(
        cylinder(0.021, 0.02, (front, 0.072, 0.08), "x"),
        cylinder(0.021, 0.02, (front, -0.072, 0.08), "x"),
        cylinder(0.03, 0.03, (front + 0.005, 0.0, 0.085), "x"),
    )


def gripper_base_mesh() -> trimesh.Trimesh:
    """The gripper's roll housing and palm, origin on the roll axis."""
    return join(
        cylinder(0.035, 0.06, (0.03, 0.0, 0.0), "x"),
        box((0.03, 0.11, 0.045), (0.07, 0.0, 0.0)),
    )


def jaw_mesh(side: float) -> trimesh.Trimesh:
    """One jaw from its hinge (origin) along +x, the fingertip bent inwards."""
    return join(
        box((0.11, 0.014, 0.035), (0.055, 0.0, 0.0)),
        box((0.025, 0.03, 0.035), (0.1, -side * 0.015, 0.0)),
        cylinder(0.012, 0.04, (0.0, 0.0, 0.0), "z"),
    )


@dataclass(frozen=True)
class Collision:
    """A collision primitive in its link's frame: a box (size), cylinder (radius, length along
    its z) or sphere (radius)."""

    kind: str
    dims: tuple[float, ...]
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)


ALONG_X = (0.0, math.pi / 2, 0.0)  # a cylinder's z turned onto the link's x


@dataclass(frozen=True)
class LinkSpec:
    """A link to write: its mesh file (None: a bare frame such as tool0), colour, collision
    primitives and (except the root) its parent joint."""

    name: str
    mesh: trimesh.Trimesh | None
    color: str
    joint: str | None = None
    joint_type: str = "fixed"
    parent: str = ""
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    limits: tuple[float, float] | None = None
    mimic: tuple[str, float] | None = None
    collisions: tuple[Collision, ...] = ()


# Where the jaws close, in the gripper_base frame: tool0, the frame the arm is steered by.
TOOL0_XYZ = (0.175, 0.0, 0.0)


def collision_shapes(profile: RobotProfile) -> dict[str, tuple[Collision, ...]]:
    """Boxes and cylinders around each link's mesh (the self-collision check uses them)."""
    hull_height = HULL_TOP + 0.03 - HULL_BOTTOM
    camera_z = HULL_TOP + 0.055
    track_height = 2 * WHEEL_RADIUS + 0.01
    jaw = (0.125, 0.03, 0.035)
    return {
        "base_link": (
            Collision(
                "box",
                (HULL_LENGTH + 0.04, 0.42, hull_height),
                (0.0, 0.0, HULL_BOTTOM + hull_height / 2),
            ),
        ),
        "chassis_cameras": (
            Collision("box", (0.04, 0.08, 0.05), (0.25, 0.0, camera_z)),
            Collision("box", (0.04, 0.08, 0.05), (-0.27, 0.0, camera_z)),
        ),
        "left_track": (
            Collision(
                "box",
                (WHEEL_BASE + 2 * WHEEL_RADIUS, TRACK_BELT_WIDTH, track_height),
                (0.0, 0.0, track_height / 2),
            ),
        ),
        "right_track": (
            Collision(
                "box",
                (WHEEL_BASE + 2 * WHEEL_RADIUS, TRACK_BELT_WIDTH, track_height),
                (0.0, 0.0, track_height / 2),
            ),
        ),
        "left_flipper": (
            Collision(
                "box",
                (FLIPPER_LENGTH + 0.14, FLIPPER_WIDTH, 2 * WHEEL_RADIUS),
                (FLIPPER_LENGTH / 2 - 0.02, 0.0, 0.0),
            ),
        ),
        "right_flipper": (
            Collision(
                "box",
                (FLIPPER_LENGTH + 0.14, FLIPPER_WIDTH, 2 * WHEEL_RADIUS),
                (FLIPPER_LENGTH / 2 - 0.02, 0.0, 0.0),
            ),
        ),
        "turret": (
            Collision(
                "cylinder",
                (0.10, SHOULDER_HEIGHT + 0.045),
                (0.0, 0.0, (SHOULDER_HEIGHT + 0.045) / 2),
            ),
        ),
        "upper_arm": (
            Collision(
                "cylinder", (0.05, UPPER_ARM_LENGTH), (UPPER_ARM_LENGTH / 2, 0.0, 0.0), ALONG_X
            ),
        ),
        "forearm": (
            Collision("cylinder", (0.045, FOREARM_LENGTH), (FOREARM_LENGTH / 2, 0.0, 0.0), ALONG_X),
        ),
        "neck_link": (Collision("box", (0.125, 0.10, 0.115), (0.019, 0.0, -0.014)),),
        "head": (Collision("box", (0.13, 0.22, 0.16), (0.04, 0.0, 0.07)),),
        "head_cameras": (Collision("box", (0.04, 0.19, 0.07), (0.12, 0.0, 0.08)),),
        "gripper_base": (Collision("box", (0.10, 0.11, 0.07), (0.045, 0.0, 0.0)),),
        "left_jaw": (Collision("box", jaw, (0.06, -0.008, 0.0)),),
        "right_jaw": (Collision("box", jaw, (0.06, 0.008, 0.0)),),
    }


def engineer_links(profile: RobotProfile) -> list[LinkSpec]:
    """Every link of the model, parents first, with its collision primitives."""
    shapes = collision_shapes(profile)
    return [
        dataclasses.replace(link, collisions=shapes.get(link.name, ()))
        for link in _engineer_links(profile)
    ]


def _engineer_links(profile: RobotProfile) -> list[LinkSpec]:
    """The links without their collision primitives."""

    def limits(name: str) -> tuple[float, float]:
        motor_limits = profile.motors[name].limits_rad
        if motor_limits is None:
            raise SystemExit(f"profile motor {name!r} has no limits")
        return motor_limits

    track_y = profile.track_width_m / 2
    flipper_y = track_y + TRACK_BELT_WIDTH / 2 + FLIPPER_WIDTH / 2 + 0.015
    front_axle = (WHEEL_BASE / 2, WHEEL_RADIUS)
    low, high = limits("gripper")
    return [
        LinkSpec("base_link", hull_mesh(), "hull"),
        LinkSpec(
            "chassis_cameras",
            chassis_cameras_mesh(),
            "lens",
            "chassis_cameras_mount",
            parent="base_link",
        ),
        LinkSpec(
            "left_track",
            track_mesh(),
            "track",
            "left_track_mount",
            parent="base_link",
            xyz=(0.0, track_y, 0.0),
        ),
        LinkSpec(
            "right_track",
            track_mesh(),
            "track",
            "right_track_mount",
            parent="base_link",
            xyz=(0.0, -track_y, 0.0),
        ),
        # Positive flipper angle lifts the tips (rotation about -y).
        LinkSpec(
            "left_flipper",
            flipper_mesh(),
            "flipper",
            "flippers",
            "revolute",
            "base_link",
            (front_axle[0], flipper_y, front_axle[1]),
            (0.0, -1.0, 0.0),
            limits("flippers"),
        ),
        LinkSpec(
            "right_flipper",
            flipper_mesh(),
            "flipper",
            "right_flipper_mimic",
            "revolute",
            "base_link",
            (front_axle[0], -flipper_y, front_axle[1]),
            (0.0, -1.0, 0.0),
            limits("flippers"),
            mimic=("flippers", 1.0),
        ),
        LinkSpec(
            "turret",
            turret_mesh(),
            "joint",
            "waist",
            "revolute",
            "base_link",
            (WAIST_X, 0.0, HULL_TOP + 0.03),
            (0.0, 0.0, 1.0),
            limits("waist"),
        ),
        # Zero pose: the arm stretched forward, level. Positive shoulder raises it.
        LinkSpec(
            "upper_arm",
            segment_mesh(UPPER_ARM_LENGTH, 0.08, 0.07),
            "arm",
            "shoulder",
            "revolute",
            "turret",
            (0.0, 0.0, SHOULDER_HEIGHT),
            (0.0, -1.0, 0.0),
            limits("shoulder"),
        ),
        # Positive elbow folds the forearm down.
        LinkSpec(
            "forearm",
            segment_mesh(FOREARM_LENGTH, 0.07, 0.06),
            "arm",
            "elbow",
            "revolute",
            "upper_arm",
            (UPPER_ARM_LENGTH, 0.0, 0.0),
            (0.0, 1.0, 0.0),
            limits("elbow"),
        ),
        # Positive neck tilts the head down.
        LinkSpec(
            "neck_link",
            neck_mesh(),
            "joint",
            "neck",
            "revolute",
            "forearm",
            (FOREARM_LENGTH, 0.0, 0.0),
            (0.0, 1.0, 0.0),
            limits("neck"),
        ),
        LinkSpec(
            "head",
            head_mesh(),
            "head",
            "head_pan",
            "revolute",
            "neck_link",
            (0.04, 0.0, 0.04),
            (0.0, 0.0, 1.0),
            limits("head_pan"),
        ),
        LinkSpec("head_cameras", head_cameras_mesh(), "lens", "head_cameras_mount", parent="head"),
        LinkSpec(
            "gripper_base",
            gripper_base_mesh(),
            "gripper",
            "gripper_roll",
            "revolute",
            "neck_link",
            (0.07, 0.0, -0.04),
            (1.0, 0.0, 0.0),
            limits("gripper_roll"),
        ),
        # Each jaw turns by the gripper angle: 0 closed, positive opens.
        LinkSpec(
            "left_jaw",
            jaw_mesh(1.0),
            "gripper",
            "gripper",
            "revolute",
            "gripper_base",
            (0.085, 0.035, 0.0),
            (0.0, 0.0, 1.0),
            (low, high),
        ),
        LinkSpec(
            "right_jaw",
            jaw_mesh(-1.0),
            "gripper",
            "right_jaw_mimic",
            "revolute",
            "gripper_base",
            (0.085, -0.035, 0.0),
            (0.0, 0.0, 1.0),
            (-high, -low),
            mimic=("gripper", -1.0),
        ),
        LinkSpec("tool0", None, "", "tool0_fixed_joint", parent="gripper_base", xyz=TOOL0_XYZ),
    ]


def _number(value: float) -> str:
    text = f"{value:.6f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def _triple(values: Sequence[float]) -> str:
    return " ".join(_number(v) for v in values)


def _geometry(shape: Collision) -> str:
    if shape.kind == "box":
        return f'<box size="{_triple(shape.dims)}"/>'
    if shape.kind == "cylinder":
        radius, length = shape.dims
        return f'<cylinder radius="{_number(radius)}" length="{_number(length)}"/>'
    return f'<sphere radius="{_number(shape.dims[0])}"/>'


def urdf_text(profile: RobotProfile, links: list[LinkSpec]) -> str:
    """The URDF document for the links."""
    lines = [
        '<?xml version="1.0"?>',
        "<!-- Low-poly Servosila Engineer, generated by tools/make_engineer_model.py.",
        "     Proportions are approximate; joint names and limits come from the robot",
        f"     profile ({Path(profile.source).name}). Do not edit by hand: rerun the script. -->",
        '<robot name="servosila_engineer">',
    ]
    for name, rgba in COLORS.items():
        lines.append(f'  <material name="{name}"><color rgba="{_triple(rgba)}"/></material>')
    for link in links:
        if link.mesh is None and not link.collisions:
            lines.append(f'  <link name="{link.name}"/>')
            continue
        lines.append(f'  <link name="{link.name}">')
        if link.mesh is not None:
            lines += [
                "    <visual>",
                f'      <geometry><mesh filename="meshes/{link.name}.stl"/></geometry>',
                f'      <material name="{link.color}"/>',
                "    </visual>",
            ]
        for shape in link.collisions:
            lines += [
                "    <collision>",
                f'      <origin xyz="{_triple(shape.xyz)}" rpy="{_triple(shape.rpy)}"/>',
                f"      <geometry>{_geometry(shape)}</geometry>",
                "    </collision>",
            ]
        lines.append("  </link>")
    for link in links:
        if link.joint is None:
            continue
        lines += [
            f'  <joint name="{link.joint}" type="{link.joint_type}">',
            f'    <parent link="{link.parent}"/>',
            f'    <child link="{link.name}"/>',
            f'    <origin xyz="{_triple(link.xyz)}" rpy="0 0 0"/>',
        ]
        if link.joint_type != "fixed":
            lines.append(f'    <axis xyz="{_triple(link.axis)}"/>')
        if link.limits is not None:
            lower, upper = link.limits
            lines.append(
                f'    <limit lower="{lower!r}" upper="{upper!r}" effort="50" velocity="1"/>'
            )
        if link.mimic is not None:
            source, multiplier = link.mimic
            lines.append(f'    <mimic joint="{source}" multiplier="{_number(multiplier)}"/>')
        lines.append("  </joint>")
    lines.append("</robot>")
    return "\n".join(lines) + "\n"


def binary_stl(mesh: trimesh.Trimesh) -> bytes:
    """Binary STL with a fixed header, so that reruns give identical bytes."""
    triangles = np.asarray(mesh.triangles, dtype=np.float64)
    normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    lengths = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.divide(normals, lengths, out=np.zeros_like(normals), where=lengths > 0)
    record = np.dtype([("normal", "<f4", 3), ("vertices", "<f4", (3, 3)), ("attr", "<u2")])
    data = np.zeros(len(triangles), dtype=record)
    data["normal"] = normals
    data["vertices"] = triangles
    header = b"ocu low-poly Servosila Engineer (approximate)".ljust(80, b" ")
    return header + struct.pack("<I", len(triangles)) + data.tobytes()


def write_model(out_dir: Path, profile: RobotProfile) -> list[Path]:
    """Write the URDF and its meshes; returns the files written."""
    links = engineer_links(profile)
    mesh_dir = out_dir / "meshes"
    mesh_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for link in links:
        if link.mesh is None:
            continue
        path = mesh_dir / f"{link.name}.stl"
        path.write_bytes(binary_stl(link.mesh))
        written.append(path)
    urdf = out_dir / "engineer.urdf"
    urdf.write_text(urdf_text(profile, links), encoding="utf-8")
    written.append(urdf)
    return written


def main(argv: list[str] | None = None) -> int:
    """Command line entry point."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("assets"), help="output folder")
    parser.add_argument("--profile", type=Path, default=None, help="robot profile TOML")
    args = parser.parse_args(argv)
    profile = load_profile(args.profile)
    files = write_model(args.out, profile)
    total = sum(path.stat().st_size for path in files)
    print(f"wrote {len(files)} files, {total / 1024:.0f} KiB, into {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
