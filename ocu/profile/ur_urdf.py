"""A URDF for a Universal Robots arm, written from its profile's DH parameters (docs/ur.md).

The frames follow Universal_Robots_ROS2_Description (urdf/ur_macro.xacro, 2.4.5):
`base_link` (REP-103: x forward) -> `base_link_inertia` turned 180° about z (the controller's
base frame, where the DH chain starts) -> shoulder_link ... wrist_3_link through the six
joints named as in the profile, each turning about its link's z; `base` is `base_link` turned
180° about z (the controller's "Base" coordinates), `flange` and `tool0` sit on wrist_3_link
as the macro puts them (tool0 = the controller's tool flange frame, z out of the flange).
Joint i's origin is the constant part of the DH product Rz(θ)·Tz(d)·Tx(a)·Rx(α) between two
joint rotations, as UR's calibration writes default_kinematics.yaml: Tz(d1) for the shoulder,
then Tx(a[i-1])·Rx(α[i-1])·Tz(d[i]).

The visuals are primitives, not UR's meshes: a cylinder per joint housing and per link tube,
sized from UR's published radii for the UR5e (physical_parameters.yaml) scaled by the square
root of the arm's reach. The upper arm and forearm tubes are offset along the joint axes as
the real links are (shoulder_offset and elbow_offset, likewise scaled). No collision or
inertial elements. The shipped files (ocu/profiles/ur/<name>.urdf) are this module's output:
`python -m ocu.profile.ur_urdf` rewrites them, and a test checks they are unchanged.
"""

from __future__ import annotations

import hashlib
import math
import os
import sys
from importlib import resources
from pathlib import Path

from ocu.files import write_text_atomically
from ocu.profile.ur import UrArmProfile, load_ur_profile, shipped_ur_profiles

# UR5e, Universal_Robots_ROS2_Description config/ur5e/physical_parameters.yaml (m).
_UR5E_REACH_M = 0.425 + 0.3922
_SHOULDER_RADIUS_M = 0.060
_UPPER_ARM_RADIUS_M = 0.054
_ELBOW_RADIUS_M = 0.060
_FOREARM_RADIUS_M = 0.040
_WRIST_RADIUS_M = 0.045
_BASE_RADIUS_M = 0.075
_SHOULDER_OFFSET_M = 0.138
_ELBOW_OFFSET_M = 0.007
_FLANGE_RADIUS_M = 0.0315  # the ISO 9409-1-50-4-M6 tool flange, 63 mm across
_FLANGE_M = 0.01  # the flange's thickness, drawn (assumed)

_COLOURS = {
    "ur_grey": (0.78, 0.80, 0.82, 1.0),
    "ur_blue": (0.42, 0.62, 0.80, 1.0),
    "ur_dark": (0.20, 0.22, 0.25, 1.0),
}
_LINKS = (
    "shoulder_link",
    "upper_arm_link",
    "forearm_link",
    "wrist_1_link",
    "wrist_2_link",
    "wrist_3_link",
)
_HALF_PI = math.pi / 2.0


def _number(value: float) -> str:
    text = f"{value:.9g}"
    return "0" if float(text) == 0.0 else text


def _vector(values: tuple[float, float, float]) -> str:
    return " ".join(_number(v) for v in values)


def _origin(xyz: tuple[float, float, float], rpy: tuple[float, float, float]) -> str:
    return f'<origin xyz="{_vector(xyz)}" rpy="{_vector(rpy)}"/>'


def _cylinder(
    radius: float, length: float, xyz: tuple[float, float, float], along: str, colour: str
) -> list[str]:
    """A visual cylinder centred at xyz with its axis along x, y or z of the link frame."""
    rpy = {"x": (0.0, _HALF_PI, 0.0), "y": (_HALF_PI, 0.0, 0.0), "z": (0.0, 0.0, 0.0)}[along]
    return [
        "    <visual>",
        f"      {_origin(xyz, rpy)}",
        f'      <geometry><cylinder radius="{_number(radius)}" length="{_number(length)}"/>'
        "</geometry>",
        f'      <material name="{colour}"/>',
        "    </visual>",
    ]


def _link(name: str, visuals: list[str]) -> list[str]:
    if not visuals:
        return [f'  <link name="{name}"/>']
    return [f'  <link name="{name}">', *visuals, "  </link>"]


def _fixed(
    name: str,
    parent: str,
    child: str,
    xyz: tuple[float, float, float],
    rpy: tuple[float, float, float],
) -> list[str]:
    return [
        f'  <joint name="{name}" type="fixed">',
        f'    <parent link="{parent}"/>',
        f'    <child link="{child}"/>',
        f"    {_origin(xyz, rpy)}",
        "  </joint>",
    ]


def _visuals(arm: UrArmProfile) -> dict[str, list[str]]:
    """Each link's primitives, in its own frame (z: the axis of the joint that turns it)."""
    d = [j.dh_d_m for j in arm.joints]
    a = [j.dh_a_m for j in arm.joints]
    reach = abs(a[1]) + abs(a[2])
    scale = math.sqrt(reach / _UR5E_REACH_M) if reach > 0 else 1.0
    r_shoulder, r_upper = _SHOULDER_RADIUS_M * scale, _UPPER_ARM_RADIUS_M * scale
    r_elbow, r_fore = _ELBOW_RADIUS_M * scale, _FOREARM_RADIUS_M * scale
    r_wrist = _WRIST_RADIUS_M * scale
    shoulder_off, elbow_off = _SHOULDER_OFFSET_M * scale, _ELBOW_OFFSET_M * scale
    base_height = max(d[0] - r_shoulder, 0.01)
    wrist_1_z = d[3]
    visuals: dict[str, list[str]] = {
        # The base: a drum from the mounting plate up to the shoulder housing.
        "base_link_inertia": _cylinder(
            _BASE_RADIUS_M * scale, base_height, (0.0, 0.0, base_height / 2.0), "z", "ur_dark"
        ),
        # The pan joint's housing (vertical) and the lift joint's (along -y: Rx(α1) z).
        "shoulder_link": [
            *_cylinder(r_shoulder, 2.0 * r_shoulder, (0.0, 0.0, -r_shoulder / 2.0), "z", "ur_blue"),
        ],
        "upper_arm_link": [
            *_cylinder(
                r_shoulder,
                shoulder_off + r_shoulder,
                (0.0, 0.0, shoulder_off / 2.0),
                "z",
                "ur_blue",
            ),
            *_cylinder(r_upper, abs(a[1]), (a[1] / 2.0, 0.0, shoulder_off), "x", "ur_grey"),
            *_cylinder(
                r_elbow,
                shoulder_off - elbow_off + 2.0 * r_elbow,
                (a[1], 0.0, (shoulder_off + elbow_off) / 2.0),
                "z",
                "ur_blue",
            ),
        ],
        "forearm_link": [
            *_cylinder(r_fore, abs(a[2]), (a[2] / 2.0, 0.0, elbow_off), "x", "ur_grey"),
            # Up to wrist 1's housing (which is coaxial: the two abut rather than overlap).
            *_cylinder(
                r_wrist,
                wrist_1_z - r_wrist - elbow_off + r_fore,
                (a[2], 0.0, (wrist_1_z - r_wrist + elbow_off - r_fore) / 2.0),
                "z",
                "ur_grey",
            ),
        ],
        # Wrist 1's housing; wrist 2 turns about -y of this frame, d5 along it.
        "wrist_1_link": [
            *_cylinder(r_wrist, 2.0 * r_wrist, (0.0, 0.0, 0.0), "z", "ur_blue"),
            *_cylinder(
                r_wrist, d[4] - r_wrist, (0.0, -(d[4] - r_wrist) / 2.0, 0.0), "y", "ur_grey"
            ),
        ],
        # Wrist 2's housing; wrist 3 turns about +y of this frame, d6 along it.
        "wrist_2_link": [
            *_cylinder(r_wrist, 2.0 * r_wrist, (0.0, 0.0, 0.0), "z", "ur_blue"),
            *_cylinder(
                r_wrist,
                d[5] - r_wrist - _FLANGE_M,
                (0.0, (d[5] - r_wrist - _FLANGE_M) / 2.0, 0.0),
                "y",
                "ur_grey",
            ),
        ],
        # Wrist 3's housing ends at the flange (z = 0 of this frame is the flange face).
        "wrist_3_link": [
            *_cylinder(r_wrist, r_wrist, (0.0, 0.0, -r_wrist / 2.0 - _FLANGE_M), "z", "ur_blue"),
            *_cylinder(_FLANGE_RADIUS_M, _FLANGE_M, (0.0, 0.0, -_FLANGE_M / 2.0), "z", "ur_dark"),
        ],
    }
    return visuals


def ur_urdf(arm: UrArmProfile) -> str:
    """The URDF text of a UR arm; see the module docstring."""
    d = [j.dh_d_m for j in arm.joints]
    a = [j.dh_a_m for j in arm.joints]
    alpha = [j.dh_alpha_rad for j in arm.joints]
    visuals = _visuals(arm)
    lines = [
        '<?xml version="1.0"?>',
        f"<!-- {arm.name}: generated by ocu.profile.ur_urdf from the profile's DH parameters",
        "     (python -m ocu.profile.ur_urdf); frames as Universal_Robots_ROS2_Description's",
        "     ur_macro.xacro; visuals are primitives (docs/ur.md). Effort limits: not in the",
        "     profile (0). -->",
        f'<robot name="{arm.name}">',
    ]
    for name, rgba in _COLOURS.items():
        lines.append(f'  <material name="{name}"><color rgba="{_vector(rgba[:3])} 1"/></material>')
    lines += _link("base_link", [])
    lines += _link("base_link_inertia", visuals["base_link_inertia"])
    lines += _fixed(
        "base_link-base_link_inertia", "base_link", "base_link_inertia", (0, 0, 0), (0, 0, math.pi)
    )
    parent = "base_link_inertia"
    for index, (joint, child) in enumerate(zip(arm.joints, _LINKS, strict=True)):
        if index == 0:
            xyz, roll = (0.0, 0.0, d[0]), 0.0
        else:
            # Tx(a)·Rx(α)·Tz(d): Rx(α) turns the z offset into (0, -sin α, cos α)·d.
            prev = index - 1
            xyz = (
                a[prev],
                -math.sin(alpha[prev]) * d[index],
                math.cos(alpha[prev]) * d[index],
            )
            roll = alpha[prev]
        lines += _link(child, visuals[child])
        kind = "revolute"
        limit = f'velocity="{_number(joint.max_speed_rad_s)}" effort="0"'
        if joint.min_rad is None or joint.max_rad is None:
            kind = "continuous"
        else:
            limit = f'lower="{_number(joint.min_rad)}" upper="{_number(joint.max_rad)}" ' + limit
        lines += [
            f'  <joint name="{joint.name}" type="{kind}">',
            f'    <parent link="{parent}"/>',
            f'    <child link="{child}"/>',
            f"    {_origin(xyz, (roll, 0.0, 0.0))}",
            '    <axis xyz="0 0 1"/>',
            f"    <limit {limit}/>",
            "  </joint>",
        ]
        parent = child
    if abs(a[5]) > 0.0 or abs(alpha[5]) > 0.0:
        # A last DH row with a or α: the flange frame is that far past wrist 3's.
        lines += _link("wrist_3_dh", [])
        lines += _fixed(
            "wrist_3_link-dh", "wrist_3_link", "wrist_3_dh", (a[5], 0, 0), (alpha[5], 0, 0)
        )
        parent = "wrist_3_dh"
    lines += _link("ft_frame", [])
    lines += _fixed("wrist_3_link-ft_frame", parent, "ft_frame", (0, 0, 0), (math.pi, 0, 0))
    lines += _link("base", [])
    lines += _fixed("base_link-base_fixed_joint", "base_link", "base", (0, 0, 0), (0, 0, math.pi))
    lines += _link("flange", [])
    lines += _fixed("wrist_3-flange", parent, "flange", (0, 0, 0), (0, -_HALF_PI, -_HALF_PI))
    lines += _link("tool0", [])
    lines += _fixed("flange-tool0", "flange", "tool0", (0, 0, 0), (_HALF_PI, 0, _HALF_PI))
    lines.append("</robot>")
    return "\n".join(lines) + "\n"


def shipped_urdf_path(name: str) -> Path:
    """Where the shipped URDF of a shipped UR profile is (ocu/profiles/ur/<name>.urdf)."""
    return Path(str(resources.files("ocu") / "profiles" / "ur" / f"{name}.urdf"))


def ur_urdf_path(arm: UrArmProfile) -> Path:
    """The URDF a UR profile's robot is drawn and steered with.

    `<stem>.urdf` beside the profile's TOML when there is one (the shipped profiles have
    theirs; a user may put a vendor URDF with meshes there), else the generated text written
    once to the user's cache folder (`$XDG_CACHE_HOME/ocu/urdf`, named by its content).
    """
    if arm.source:
        beside = Path(arm.source).with_suffix(".urdf")
        if beside.is_file():
            return beside
    text = ur_urdf(arm)
    digest = hashlib.sha256(text.encode("utf-8")).hexdigest()[:12]
    cache = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "ocu" / "urdf"
    path = cache / f"{arm.name}-{digest}.urdf"
    if not path.is_file():
        path.parent.mkdir(parents=True, exist_ok=True)
        write_text_atomically(path, text)
    return path


def main(argv: list[str] | None = None) -> int:
    """Rewrite the shipped URDFs from the shipped profiles; `--check`: only compare."""
    args = sys.argv[1:] if argv is None else argv
    check = "--check" in args
    stale = []
    for name in shipped_ur_profiles():
        text = ur_urdf(load_ur_profile(name))
        path = shipped_urdf_path(name)
        current = path.read_text(encoding="utf-8") if path.is_file() else None
        if current == text:
            continue
        stale.append(str(path))
        if not check:
            write_text_atomically(path, text)
    for path_text in stale:
        print(f"{'differs' if check else 'written'}: {path_text}")
    return 1 if check and stale else 0


if __name__ == "__main__":
    raise SystemExit(main())
