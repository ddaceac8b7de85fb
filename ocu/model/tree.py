"""Kinematic tree of a robot model: constant link-to-parent transforms and joint motion.

Each link keeps the constant transform of its parent joint (the URDF joint origin) and the
joint's axis. Absolute transforms are recomputed from the root after every change, never
accumulated, so the model cannot drift apart however many updates it receives. Numpy only:
no Qt, no OpenGL.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

Matrix = npt.NDArray[np.float64]

JOINT_TYPES = ("fixed", "revolute", "continuous", "prismatic")
_ROTATING = ("revolute", "continuous")


class TreeError(ValueError):
    """The joints do not form one tree, or a joint name or value is wrong."""


@dataclass(frozen=True)
class Mimic:
    """A joint that follows another: value = multiplier * source + offset."""

    joint: str
    multiplier: float = 1.0
    offset: float = 0.0


@dataclass(frozen=True)
class Joint:
    """A joint between two links: constant origin in the parent frame plus motion on an axis."""

    name: str
    type: str
    parent: str
    child: str
    origin: Matrix
    axis: tuple[float, float, float] = (1.0, 0.0, 0.0)
    limits: tuple[float, float] | None = None
    mimic: Mimic | None = None

    def __post_init__(self) -> None:
        if self.type not in JOINT_TYPES:
            raise TreeError(
                f"joint {self.name!r}: unknown joint type {self.type!r} "
                f"(expected one of {', '.join(JOINT_TYPES)})"
            )
        if np.shape(self.origin) != (4, 4):
            raise TreeError(f"joint {self.name!r}: origin must be a 4x4 matrix")
        norm = math.sqrt(sum(a * a for a in self.axis))
        if self.type != "fixed" and not norm > 1e-12:
            raise TreeError(f"joint {self.name!r}: axis must not be zero")
        if self.limits is not None and not self.limits[0] <= self.limits[1]:
            raise TreeError(f"joint {self.name!r}: lower limit above upper limit")

    @property
    def unit_axis(self) -> tuple[float, float, float]:
        """The axis scaled to length one."""
        norm = math.sqrt(sum(a * a for a in self.axis)) or 1.0
        return (self.axis[0] / norm, self.axis[1] / norm, self.axis[2] / norm)


def transform(
    xyz: Sequence[float] = (0.0, 0.0, 0.0), rpy: Sequence[float] = (0.0, 0.0, 0.0)
) -> Matrix:
    """4x4 transform from a translation and URDF roll-pitch-yaw (fixed axes X, Y, Z)."""
    roll, pitch, yaw = (float(v) for v in rpy)
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    matrix = np.eye(4)
    matrix[:3, :3] = [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]
    matrix[:3, 3] = [float(v) for v in xyz]
    return matrix


def axis_rotation(axis: Sequence[float], angle_rad: float) -> Matrix:
    """4x4 rotation by an angle about a unit axis through the origin (Rodrigues)."""
    x, y, z = (float(v) for v in axis)
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    t = 1.0 - c
    matrix = np.eye(4)
    matrix[:3, :3] = [
        [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
        [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
        [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
    ]
    return matrix


class KinematicTree:
    """Links joined by joints, with joint positions and the absolute transforms they give.

    set_position() and set_positions() only store values; the absolute transforms are
    recomputed from the root, in one pass over the links in parent-before-child order, the
    next time they are read. Nothing is ever multiplied onto a previous result.
    """

    def __init__(self, root: str, links: Iterable[str], joints: Iterable[Joint]) -> None:
        link_names = list(links)
        joint_list = list(joints)
        _check_names(link_names, joint_list)
        self.root = root
        order, parent_joint = _topological_order(root, link_names, joint_list)
        self._joints = {joint.name: joint for joint in joint_list}
        self._parent_joint = parent_joint
        self.links: tuple[str, ...] = tuple(order)
        self._index = {name: i for i, name in enumerate(order)}
        count = len(order)
        self._parent = np.full(count, -1, dtype=np.int64)
        self._origin = np.tile(np.eye(4), (count, 1, 1))
        self._axis = np.zeros((count, 3))
        self._kind = np.zeros(count, dtype=np.int8)  # 0 fixed, 1 rotating, 2 prismatic
        self._source = np.zeros(count, dtype=np.int64)  # index into the value vector
        self._multiplier = np.zeros(count)
        self._offset = np.zeros(count)
        actuated = [j for j in joint_list if j.type != "fixed" and j.mimic is None]
        self.actuated_joints: tuple[str, ...] = tuple(
            sorted((j.name for j in actuated), key=lambda n: self._index[self._joints[n].child])
        )
        self._value_index = {name: i for i, name in enumerate(self.actuated_joints)}
        self._values = np.zeros(len(self.actuated_joints))
        for joint in joint_list:
            if joint.mimic is not None:
                source = self._joints.get(joint.mimic.joint)
                if source is None or source.type == "fixed" or source.mimic is not None:
                    raise TreeError(
                        f"joint {joint.name!r}: mimics {joint.mimic.joint!r}, which is not "
                        "a moving joint of this model"
                    )
        for joint in joint_list:
            i = self._index[joint.child]
            self._parent[i] = self._index[joint.parent]
            self._origin[i] = joint.origin
            self._axis[i] = joint.unit_axis
            if joint.type == "fixed":
                continue
            self._kind[i] = 2 if joint.type == "prismatic" else 1
            if joint.mimic is None:
                self._source[i] = self._value_index[joint.name]
                self._multiplier[i] = 1.0
            else:
                self._source[i] = self._value_index[joint.mimic.joint]
                self._multiplier[i] = joint.mimic.multiplier
                self._offset[i] = joint.mimic.offset
        self._rotating = self._kind == 1
        self._prismatic = self._kind == 2
        self._levels = _levels(self._parent)
        self._world = np.tile(np.eye(4), (count, 1, 1))
        self._dirty = True
        self.recompute_count = 0

    # Structure.

    @property
    def joints(self) -> Mapping[str, Joint]:
        """Every joint by name, fixed and mimic ones included."""
        return self._joints

    def joint(self, name: str) -> Joint:
        """One joint by name; TreeError if unknown."""
        try:
            return self._joints[name]
        except KeyError:
            raise TreeError(
                f"unknown joint {name!r}; this model has: {', '.join(self.actuated_joints)}"
            ) from None

    def parent_joint(self, link: str) -> Joint | None:
        """The joint that carries a link (None for the root)."""
        return self._parent_joint.get(link)

    def links_moved_by(self, joint_name: str) -> tuple[str, ...]:
        """Links whose own joint is this joint or mimics it (not their descendants)."""
        return tuple(
            link
            for link, joint in self._parent_joint.items()
            if joint.name == joint_name
            or (joint.mimic is not None and joint.mimic.joint == joint_name)
        )

    def subtree(self, link: str) -> tuple[str, ...]:
        """A link and every link below it."""
        start = self._index[link]
        inside = np.zeros(len(self.links), dtype=bool)
        inside[start] = True
        for i in range(start + 1, len(self.links)):
            parent = self._parent[i]
            if parent >= 0 and inside[parent]:
                inside[i] = True
        return tuple(name for name, flag in zip(self.links, inside, strict=True) if flag)

    def copy(self) -> KinematicTree:
        """A tree with the same structure and its own joint positions (copied)."""
        clone = object.__new__(KinematicTree)
        clone.__dict__.update(self.__dict__)
        clone._values = self._values.copy()
        clone._world = self._world.copy()
        clone.recompute_count = 0
        return clone

    # Joint positions.

    def set_position(self, name: str, value: float) -> None:
        """Set one actuated joint (rad or m); absolute transforms follow on the next read."""
        index = self._value_index.get(name)
        if index is None:
            self._raise_not_actuated(name)
        self._values[index] = value
        self._dirty = True

    def set_positions(self, values: Mapping[str, float]) -> None:
        """Set several actuated joints at once."""
        for name, value in values.items():
            self.set_position(name, value)

    def position(self, name: str) -> float:
        """Current value of an actuated joint."""
        index = self._value_index.get(name)
        if index is None:
            self._raise_not_actuated(name)
        return float(self._values[index])

    def positions(self) -> dict[str, float]:
        """Every actuated joint's value."""
        return {name: float(self._values[i]) for name, i in self._value_index.items()}

    def _raise_not_actuated(self, name: str) -> None:
        joint = self.joint(name)
        if joint.mimic is not None:
            raise TreeError(f"joint {name!r} mimics {joint.mimic.joint!r}: set that one")
        raise TreeError(f"joint {name!r} is fixed")

    # Transforms.

    def world_transforms(self) -> Mapping[str, Matrix]:
        """Absolute 4x4 transform of every link (read-only views, valid until a change)."""
        world = self._recompute()
        return {name: world[i] for i, name in enumerate(self.links)}

    def world_transform(self, link: str) -> Matrix:
        """Absolute 4x4 transform of one link."""
        result: Matrix = self._recompute()[self._index[link]].copy()
        return result

    def world_array(self) -> npt.NDArray[np.float64]:
        """Absolute transforms as an (n_links, 4, 4) array in the order of `links`."""
        return self._recompute().copy()

    def _recompute(self) -> npt.NDArray[np.float64]:
        if not self._dirty:
            return self._world
        # A model without a moving joint has no values to index: every link is fixed.
        source = self._values[self._source] if self._values.size else 0.0
        q = source * self._multiplier + self._offset
        motion = np.tile(np.eye(4), (len(self.links), 1, 1))
        if self._rotating.any():
            rot = self._rotating
            motion[rot, :3, :3] = _rotation_matrices(self._axis[rot], q[rot])
        if self._prismatic.any():
            pri = self._prismatic
            motion[pri, :3, 3] = self._axis[pri] * q[pri, None]
        local = self._origin @ motion
        world = self._world
        world[0] = local[0]
        for level in self._levels:
            world[level] = world[self._parent[level]] @ local[level]
        self._dirty = False
        self.recompute_count += 1
        return world


def _rotation_matrices(
    axes: npt.NDArray[np.float64], angles: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    """Rodrigues rotations, one per row of unit axes and angles."""
    c = np.cos(angles)[:, None, None]
    s = np.sin(angles)[:, None, None]
    x, y, z = axes[:, 0], axes[:, 1], axes[:, 2]
    zero = np.zeros_like(x)
    cross = np.stack(
        [
            np.stack([zero, -z, y], axis=-1),
            np.stack([z, zero, -x], axis=-1),
            np.stack([-y, x, zero], axis=-1),
        ],
        axis=-2,
    )
    outer = axes[:, :, None] * axes[:, None, :]
    result: npt.NDArray[np.float64] = c * np.eye(3) + s * cross + (1.0 - c) * outer
    return result


def _check_names(links: list[str], joints: list[Joint]) -> None:
    seen: set[str] = set()
    for name in links:
        if name in seen:
            raise TreeError(f"two links are named {name!r}")
        seen.add(name)
    joint_names: set[str] = set()
    for joint in joints:
        if joint.name in joint_names:
            raise TreeError(f"two joints are named {joint.name!r}")
        joint_names.add(joint.name)
        for role, link in (("parent", joint.parent), ("child", joint.child)):
            if link not in seen:
                raise TreeError(f"joint {joint.name!r}: {role} link {link!r} is not defined")
        if joint.parent == joint.child:
            raise TreeError(f"joint {joint.name!r}: joins link {joint.parent!r} to itself")


def _topological_order(
    root: str, links: list[str], joints: list[Joint]
) -> tuple[list[str], dict[str, Joint]]:
    """Links parent-before-child from the root; TreeError on a cycle or a second parent."""
    if root not in links:
        raise TreeError(f"root link {root!r} is not defined")
    parent_joint: dict[str, Joint] = {}
    for joint in joints:
        other = parent_joint.get(joint.child)
        if other is not None:
            raise TreeError(
                f"link {joint.child!r} has two parent joints ({other.name!r} and "
                f"{joint.name!r}); a model must be a tree"
            )
        parent_joint[joint.child] = joint
    if root in parent_joint:
        raise TreeError(f"root link {root!r} has a parent joint {parent_joint[root].name!r}")
    children: dict[str, list[str]] = {name: [] for name in links}
    for joint in joints:
        children[joint.parent].append(joint.child)
    order: list[str] = []
    stack = [root]
    while stack:
        link = stack.pop()
        order.append(link)
        stack.extend(reversed(children[link]))
    if len(order) < len(links):
        missing = [name for name in links if name not in set(order)]
        cycle = _find_cycle(missing, parent_joint)
        if cycle:
            raise TreeError("joints form a cycle: " + " -> ".join(cycle))
        raise TreeError(f"links not connected to the root {root!r}: {', '.join(sorted(missing))}")
    # Breadth by depth keeps every parent before its children, which _levels relies on.
    depth = {root: 0}
    for link in order[1:]:
        depth[link] = depth[parent_joint[link].parent] + 1
    order.sort(key=lambda name: depth[name])
    return order, parent_joint


def _find_cycle(links: list[str], parent_joint: Mapping[str, Joint]) -> list[str]:
    """Joint names around a cycle among these links, or [] if none."""
    for start in links:
        path: list[str] = []
        seen: dict[str, int] = {}
        link = start
        while link in parent_joint and link not in seen:
            seen[link] = len(path)
            joint = parent_joint[link]
            path.append(joint.name)
            link = joint.parent
        if link in seen:
            cycle = path[seen[link] :]
            return [*cycle, cycle[0]]
    return []


def _levels(parent: npt.NDArray[np.int64]) -> list[npt.NDArray[np.int64]]:
    """Link indices grouped by depth (root excluded), for one batched product per level."""
    depth = np.zeros(len(parent), dtype=np.int64)
    for i in range(1, len(parent)):
        depth[i] = depth[parent[i]] + 1
    return [np.flatnonzero(depth == d) for d in range(1, int(depth.max(initial=0)) + 1)]
