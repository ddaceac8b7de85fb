"""A serial chain between two links of a kinematic tree: forward kinematics and the Jacobian.

The chain is read off the tree (`ocu.model.tree.KinematicTree`): the joints on the path from
the base link down to the tip link. Its variables are the actuated joints on that path, in
order from the base (or the ones named in `variables`); a mimic joint on the path moves with
its source (its Jacobian column is added to the source's, times the multiplier). A moving
joint that is not a variable (one the robot cannot command, such as the Engineer's gripper
roll) is held at a value: the tree's at first, then what `hold()` says (a reading). Poses are
4x4 transforms of the tip in the base link's frame.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ocu.model.tree import Joint, KinematicTree, Matrix, axis_rotation

Vector = npt.NDArray[np.float64]


class ChainError(ValueError):
    """The two links are not joined by a chain of the tree, or a value is wrong."""


@dataclass(frozen=True)
class _Step:
    """One joint on the path: its constant origin and how it moves."""

    joint: Joint
    origin: Matrix
    axis: Vector
    kind: int  # 0 fixed, 1 revolute/continuous, 2 prismatic
    variable: int  # index of the chain variable that drives it, -1 if none
    multiplier: float
    offset: float
    source: str  # the joint whose value drives it (itself, or what it mimics)


class Chain:
    """The joints from `base` down to `tip`; see the module docstring."""

    def __init__(
        self,
        tree: KinematicTree,
        base: str,
        tip: str,
        variables: Sequence[str] | None = None,
    ) -> None:
        if base not in tree.links:
            raise ChainError(f"unknown link {base!r}; this model has: {', '.join(tree.links)}")
        if tip not in tree.links:
            raise ChainError(f"unknown link {tip!r}; this model has: {', '.join(tree.links)}")
        path: list[Joint] = []
        link = tip
        while link != base:
            joint = tree.parent_joint(link)
            if joint is None:
                raise ChainError(f"link {base!r} is not above {tip!r} in the tree")
            path.append(joint)
            link = joint.parent
        path.reverse()
        self.tree = tree
        self.base = base
        self.tip = tip
        on_path = [j.name for j in path if j.type != "fixed" and j.mimic is None]
        if variables is None:
            names = on_path
        else:
            names = list(variables)
            for name in names:
                if name not in on_path:
                    raise ChainError(
                        f"joint {name!r} does not move the chain {base} -> {tip} "
                        f"(its joints: {', '.join(on_path) or 'none'})"
                    )
            names.sort(key=on_path.index)
        self.joints: tuple[str, ...] = tuple(names)
        index = {name: i for i, name in enumerate(names)}
        self._held: dict[str, float] = dict(tree.positions())
        steps = []
        for joint in path:
            kind = 0 if joint.type == "fixed" else 2 if joint.type == "prismatic" else 1
            multiplier, offset, source = 1.0, 0.0, joint.name
            if kind and joint.mimic is not None:
                multiplier, offset = joint.mimic.multiplier, joint.mimic.offset
                source = joint.mimic.joint
            steps.append(
                _Step(
                    joint=joint,
                    origin=np.asarray(joint.origin, dtype=float),
                    axis=np.asarray(joint.unit_axis, dtype=float),
                    kind=kind,
                    variable=index.get(source, -1) if kind else -1,
                    multiplier=multiplier,
                    offset=offset,
                    source=source,
                )
            )
        self.held_joints: tuple[str, ...] = tuple(
            dict.fromkeys(s.source for s in steps if s.kind and s.variable < 0)
        )
        self._steps = tuple(steps)
        lower, upper = [], []
        for name in names:
            limits = tree.joint(name).limits
            low, high = limits if limits is not None else (-math.inf, math.inf)
            lower.append(low)
            upper.append(high)
        self.lower = np.asarray(lower, dtype=float)
        self.upper = np.asarray(upper, dtype=float)
        self.prismatic = np.asarray(
            [tree.joint(name).type == "prismatic" for name in names], dtype=bool
        )

    def hold(self, values: Mapping[str, float]) -> None:
        """Values for the moving joints that are not variables (others are ignored)."""
        for name in self.held_joints:
            if name in values and math.isfinite(values[name]):
                self._held[name] = float(values[name])

    def _value(self, step: _Step, values: Vector) -> float:
        source = values[step.variable] if step.variable >= 0 else self._held.get(step.source, 0.0)
        return step.multiplier * source + step.offset

    @property
    def dof(self) -> int:
        """Number of chain variables."""
        return len(self.joints)

    def vector(self, angles: Mapping[str, float], default: Vector | None = None) -> Vector:
        """The chain's variables from a name -> value map (missing ones from `default`, or 0)."""
        q = np.zeros(self.dof) if default is None else np.array(default, dtype=float)
        for i, name in enumerate(self.joints):
            if name in angles:
                q[i] = float(angles[name])
        return q

    def mapping(self, q: Sequence[float] | Vector) -> dict[str, float]:
        """Name -> value of the chain's variables."""
        return {name: float(value) for name, value in zip(self.joints, q, strict=True)}

    def _check(self, q: Sequence[float] | Vector) -> Vector:
        values = np.asarray(q, dtype=float)
        if values.shape != (self.dof,):
            raise ChainError(f"expected {self.dof} values for {', '.join(self.joints)}")
        if not np.all(np.isfinite(values)):
            raise ChainError("joint values must be finite")
        return values

    def frames(self, q: Sequence[float] | Vector) -> list[Matrix]:
        """The frame of every joint (after its motion) in the base frame, base to tip."""
        values = self._check(q)
        current = np.eye(4)
        out = []
        for step in self._steps:
            current = current @ step.origin
            if step.kind:
                current = current @ self._motion(step, self._value(step, values))
            out.append(current)
        return out

    def forward(self, q: Sequence[float] | Vector) -> Matrix:
        """The tip's pose in the base frame."""
        frames = self.frames(q)
        return frames[-1] if frames else np.eye(4)

    def axes(self, q: Sequence[float] | Vector) -> tuple[list[tuple[Vector, Vector]], Matrix]:
        """Per chain variable, the (point, unit axis) of its joint in the base frame; the tip pose.

        A mimic joint on the chain adds no entry (its source's column takes it).
        """
        values = self._check(q)
        current = np.eye(4)
        axes: list[tuple[Vector, Vector]] = [(np.zeros(3), np.zeros(3))] * self.dof
        for step in self._steps:
            current = current @ step.origin
            if step.kind:
                if step.variable >= 0 and step.joint.mimic is None:
                    axes[step.variable] = (current[:3, 3].copy(), current[:3, :3] @ step.axis)
                current = current @ self._motion(step, self._value(step, values))
        return axes, current

    @staticmethod
    def _motion(step: _Step, value: float) -> Matrix:
        if step.kind == 1:
            return axis_rotation(tuple(step.axis), value)
        motion = np.eye(4)
        motion[:3, 3] = step.axis * value
        return motion

    def jacobian(self, q: Sequence[float] | Vector) -> npt.NDArray[np.float64]:
        """The 6 x dof geometric Jacobian of the tip in the base frame: rows vx vy vz wx wy wz.

        A revolute column is (axis x (tip - joint), axis); a prismatic one (axis, 0).
        """
        values = self._check(q)
        jac = np.zeros((6, self.dof))
        current = np.eye(4)
        columns: list[tuple[int, float, int, Vector, Vector]] = []
        for step in self._steps:
            current = current @ step.origin
            if step.kind:
                if step.variable >= 0:
                    axis_world = current[:3, :3] @ step.axis
                    columns.append(
                        (
                            step.variable,
                            step.multiplier,
                            step.kind,
                            axis_world,
                            current[:3, 3].copy(),
                        )
                    )
                current = current @ self._motion(step, self._value(step, values))
        tip = current[:3, 3]
        for variable, multiplier, kind, axis_world, origin_world in columns:
            if kind == 1:
                jac[:3, variable] += multiplier * np.cross(axis_world, tip - origin_world)
                jac[3:, variable] += multiplier * axis_world
            else:
                jac[:3, variable] += multiplier * axis_world
        return jac

    def clamp(self, q: Sequence[float] | Vector) -> Vector:
        """Values moved inside the joint limits."""
        result: Vector = np.clip(np.asarray(q, dtype=float), self.lower, self.upper)
        return result

    def within_limits(self, q: Sequence[float] | Vector, tolerance: float = 1e-9) -> bool:
        """Whether every value lies inside its limits."""
        values = np.asarray(q, dtype=float)
        return bool(
            np.all(values >= self.lower - tolerance) and np.all(values <= self.upper + tolerance)
        )


def rotation_error(current: Matrix, target: Matrix) -> Vector:
    """The rotation vector (axis x angle, base frame) that turns `current` into `target`."""
    relative = target[:3, :3] @ current[:3, :3].T
    cos_angle = min(max((np.trace(relative) - 1.0) / 2.0, -1.0), 1.0)
    angle = math.acos(cos_angle)
    skew = np.array(
        [
            relative[2, 1] - relative[1, 2],
            relative[0, 2] - relative[2, 0],
            relative[1, 0] - relative[0, 1],
        ]
    )
    if angle < 1e-9:
        return 0.5 * skew
    if math.pi - angle < 1e-6:
        # Near a half turn the skew part vanishes: the axis is the dominant column of R + I.
        symmetric = (relative + np.eye(3)) / 2.0
        column = int(np.argmax(np.diag(symmetric)))
        axis = symmetric[:, column] / math.sqrt(max(symmetric[column, column], 1e-12))
        return axis * angle
    return skew * (angle / (2.0 * math.sin(angle)))
