"""Self-collision from the URDF's collision geometry: capsules and boxes per link (numpy only).

Every collision primitive of the URDF becomes a capsule (a segment swept by a ball: cylinders,
spheres, and on the arm the boxes too, along their longest side) or, on the body, stays a box.
All are conservative: the capsule contains its primitive. The checked pairs are the arm's links
against the body's (the chassis, tracks, flippers, cameras), and arm links against each other
where at least two arm joints lie between them, except neighbours (one moving joint between
them: the joint's limits keep them apart) and pairs already touching in the zero pose
(MoveIt's "adjacent" and "default" rules). An optional
ground plane keeps the arm above the floor. Along a path (`path_violation`) every pair keeps
the clearance, except one already closer at the start: it may only move apart until clear.

Distances are exact for the shapes: segment to segment (Ericson, Real-Time Collision Detection
§5.1.9) and segment to box by minimising the convex piecewise-quadratic distance over its
breakpoints, all pairs of a kind at once.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ocu.model.tree import KinematicTree, Matrix
from ocu.model.urdf import CollisionShape

Array = npt.NDArray[np.float64]
GROUND = "the ground"
EPSILON = 1e-12
# A pair's gap this little smaller than before is the same gap (rounding), not an approach.
SAME_GAP_M = 1e-6


@dataclass(frozen=True)
class Capsule:
    """A segment from `start` to `end` (link frame) swept by a ball of `radius_m`."""

    link: str
    start: Array
    end: Array
    radius_m: float


@dataclass(frozen=True)
class Box:
    """A box: its centre pose in the link frame and half its extents."""

    link: str
    pose: Matrix
    half: Array


@dataclass(frozen=True)
class Contact:
    """The closest pair: the gap between them (negative when they overlap) and their links."""

    distance_m: float
    link_a: str
    link_b: str

    def describe(self) -> str:
        """'forearm and base_link 12 mm apart' or '... overlap by 5 mm'."""
        if self.distance_m < 0.0:
            return f"{self.link_a} and {self.link_b} overlap by {-self.distance_m * 1000:.0f} mm"
        return f"{self.link_a} and {self.link_b} {self.distance_m * 1000:.0f} mm apart"


def capsule_of(link: str, shape: CollisionShape) -> Capsule:
    """The capsule around a primitive (a box along its longest side)."""
    origin = shape.origin
    center = origin[:3, 3]
    if shape.kind == "sphere":
        return Capsule(link, center.copy(), center.copy(), shape.size[0])
    if shape.kind == "cylinder":
        radius, _, length = shape.size
        axis = origin[:3, 2] * (length / 2.0)
        return Capsule(link, center - axis, center + axis, radius)
    extents = np.asarray(shape.size, dtype=float)
    longest = int(np.argmax(extents))
    others = [extents[i] for i in range(3) if i != longest]
    radius = math.hypot(others[0], others[1]) / 2.0
    axis = origin[:3, longest] * (extents[longest] / 2.0)
    return Capsule(link, center - axis, center + axis, radius)


def box_of(link: str, shape: CollisionShape) -> Box | Capsule:
    """A box stays a box; other primitives become capsules."""
    if shape.kind == "box":
        return Box(link, shape.origin.copy(), np.asarray(shape.size, dtype=float) / 2.0)
    return capsule_of(link, shape)


def _transform(matrix: Matrix, points: Array) -> Array:
    result: Array = points @ matrix[:3, :3].T + matrix[:3, 3]
    return result


def segment_distances(p1: Array, q1: Array, p2: Array, q2: Array) -> Array:
    """Distances between segments p1-q1 and p2-q2, row by row ((n, 3) arrays)."""
    d1 = q1 - p1
    d2 = q2 - p2
    r = p1 - p2
    a = np.einsum("ij,ij->i", d1, d1)
    e = np.einsum("ij,ij->i", d2, d2)
    f = np.einsum("ij,ij->i", d2, r)
    c = np.einsum("ij,ij->i", d1, r)
    b = np.einsum("ij,ij->i", d1, d2)
    denominator = a * e - b * b
    safe_a = np.where(a > EPSILON, a, 1.0)
    safe_e = np.where(e > EPSILON, e, 1.0)
    s = np.where(
        denominator > EPSILON,
        np.clip((b * f - c * e) / np.where(denominator > EPSILON, denominator, 1.0), 0.0, 1.0),
        0.0,
    )
    t = (b * s + f) / safe_e
    # t outside [0, 1]: clamp it and recompute s for that end.
    s = np.where(t < 0.0, np.clip(-c / safe_a, 0.0, 1.0), s)
    s = np.where(t > 1.0, np.clip((b - c) / safe_a, 0.0, 1.0), s)
    t = np.clip(t, 0.0, 1.0)
    # Degenerate segments (points).
    s = np.where(a <= EPSILON, 0.0, s)
    t = np.where(e <= EPSILON, np.clip(f / safe_e, 0.0, 1.0), t)
    t = np.where(e <= EPSILON, 0.0, t)
    s = np.where((a > EPSILON) & (e <= EPSILON), np.clip(-c / safe_a, 0.0, 1.0), s)
    closest1 = p1 + d1 * s[:, None]
    closest2 = p2 + d2 * t[:, None]
    result: Array = np.linalg.norm(closest1 - closest2, axis=1)
    return result


def segment_box_distances(start: Array, end: Array, half: Array) -> Array:
    """Distances from segments (in each box's own frame) to boxes centred at the origin.

    The squared distance to a box along a line is convex and piecewise quadratic; its
    minimum lies at an end, where the line crosses a face plane, or at the stationary point
    of one piece. All candidates are tried at once.
    """
    d = end - start
    with np.errstate(divide="ignore", invalid="ignore"):
        crossings = np.concatenate([(half - start) / d, (-half - start) / d], axis=1)  # (n, 6)
    crossings = np.where(np.isfinite(crossings), np.clip(crossings, 0.0, 1.0), 0.0)
    ends = np.column_stack([np.zeros(len(start)), np.ones(len(start))])
    breaks = np.sort(np.concatenate([ends, crossings], axis=1), axis=1)  # (n, 8)
    middle = (breaks[:, :-1] + breaks[:, 1:]) / 2.0  # (n, 7)
    points = start[:, None, :] + middle[:, :, None] * d[:, None, :]
    outside = np.abs(points) > half[:, None, :]
    target = np.sign(points) * half[:, None, :]
    weight = np.where(outside, d[:, None, :], 0.0)
    numerator = np.sum(weight * (target - start[:, None, :]), axis=2)
    denominator = np.sum(weight * d[:, None, :], axis=2)
    stationary = np.where(denominator > EPSILON, numerator / np.maximum(denominator, EPSILON), 0.0)
    stationary = np.clip(stationary, breaks[:, :-1], breaks[:, 1:])
    candidates = np.concatenate([breaks, stationary], axis=1)  # (n, 15)
    samples = start[:, None, :] + candidates[:, :, None] * d[:, None, :]
    gap = np.maximum(np.abs(samples) - half[:, None, :], 0.0)
    result: Array = np.sqrt(np.min(np.sum(gap * gap, axis=2), axis=1))
    return result


class CollisionModel:
    """The arm's collision pairs and their distances in any pose; see the module docstring."""

    def __init__(
        self,
        tree: KinematicTree,
        collisions: Mapping[str, Sequence[CollisionShape]],
        arm_joints: Collection[str],
        *,
        ground_z_m: float | None = None,
        reference: Mapping[str, float] | None = None,
    ) -> None:
        self.tree = tree.copy()
        arm_joints = set(arm_joints)
        moving: set[str] = set()
        for joint in arm_joints:
            for link in tree.links_moved_by(joint):
                moving.update(tree.subtree(link))
        self.arm_links = frozenset(moving)
        self._arm_joints = arm_joints
        capsules: list[Capsule] = []
        boxes: list[Box] = []
        for link, shapes in collisions.items():
            if link not in tree.links:
                continue
            for shape in shapes:
                if link in moving:
                    capsules.append(capsule_of(link, shape))
                else:
                    item = box_of(link, shape)
                    (boxes if isinstance(item, Box) else capsules).append(item)  # type: ignore[arg-type]
        self.capsules = tuple(capsules)
        self.boxes = tuple(boxes)
        self.ground_z_m = ground_z_m
        self._capsule_pairs: list[tuple[int, int]] = []
        self._box_pairs: list[tuple[int, int]] = []
        for i, one in enumerate(capsules):
            for j in range(i + 1, len(capsules)):
                if self._relevant(one.link, capsules[j].link):
                    self._capsule_pairs.append((i, j))
            for j, box in enumerate(boxes):
                if self._relevant(one.link, box.link):
                    self._box_pairs.append((i, j))
        self._ground = [i for i, c in enumerate(capsules) if c.link in moving]
        # Pairs already touching in the reference pose are parts that fit together.
        zero = dict.fromkeys(tree.actuated_joints, 0.0)
        zero.update(reference or {})
        capsule_d, box_d = self._distances(zero)
        self._capsule_pairs = [
            p for p, d in zip(self._capsule_pairs, capsule_d, strict=True) if d > 0.0
        ]
        self._box_pairs = [p for p, d in zip(self._box_pairs, box_d, strict=True) if d > 0.0]
        # The index arrays were built for the measurement above, over every pair: again, over
        # the pairs kept (else the columns of `gaps_along` are not those `pair_contact` names).
        self._prepare()

    def _relevant(self, a: str, b: str) -> bool:
        """Whether an arm joint moves the two links relative to each other (not neighbours)."""
        if a == b or (a not in self.arm_links and b not in self.arm_links):
            return False
        path = _path_joints(self.tree, a, b)
        moving = [j for j in path if self.tree.joint(j).type != "fixed"]
        if len(moving) <= 1:
            return False
        sources = set()
        for name in moving:
            mimic = self.tree.joint(name).mimic
            sources.add(mimic.joint if mimic is not None else name)
        arm = sources & self._arm_joints
        if a in self.arm_links and b in self.arm_links:
            # One arm joint between two arm links: its limits keep them apart (the forearm
            # and the gripper across the neck), as they keep neighbours apart.
            return len(arm) >= 2
        return bool(arm)

    @property
    def pair_count(self) -> int:
        """Pairs checked (ground excluded)."""
        return len(self._capsule_pairs) + len(self._box_pairs)

    @property
    def pairs(self) -> list[tuple[str, str]]:
        """The link pairs checked."""
        out = [(self.capsules[i].link, self.capsules[j].link) for i, j in self._capsule_pairs]
        out += [(self.capsules[i].link, self.boxes[j].link) for i, j in self._box_pairs]
        return out

    def _prepare(self) -> None:
        """Index arrays for the batched measurement (built once, after the pairs are known)."""
        index = {name: i for i, name in enumerate(self.tree.links)}
        self._capsule_link = np.array([index[c.link] for c in self.capsules], dtype=np.int64)
        self._capsule_start = np.array([c.start for c in self.capsules]).reshape(-1, 3)
        self._capsule_end = np.array([c.end for c in self.capsules]).reshape(-1, 3)
        self._radii = np.array([c.radius_m for c in self.capsules])
        self._ci = np.array([p[0] for p in self._capsule_pairs], dtype=np.int64)
        self._cj = np.array([p[1] for p in self._capsule_pairs], dtype=np.int64)
        self._bi = np.array([p[0] for p in self._box_pairs], dtype=np.int64)
        self._box_link = np.array(
            [index[self.boxes[j].link] for _, j in self._box_pairs], dtype=np.int64
        )
        self._box_pose = np.array([self.boxes[j].pose for _, j in self._box_pairs]).reshape(
            -1, 4, 4
        )
        self._box_half = np.array([self.boxes[j].half for _, j in self._box_pairs]).reshape(-1, 3)
        self._ground_index = np.array(self._ground, dtype=np.int64)

    def _worlds(self, poses: Sequence[Mapping[str, float]]) -> Array:
        """(poses, links, 4, 4): every link's transform in each pose."""
        worlds = np.empty((len(poses), len(self.tree.links), 4, 4))
        for k, angles in enumerate(poses):
            # Joints not given (no reading yet) sit at zero, whatever an earlier call said.
            values = dict.fromkeys(self.tree.actuated_joints, 0.0)
            values.update({n: v for n, v in angles.items() if n in values and math.isfinite(v)})
            self.tree.set_positions(values)
            worlds[k] = self.tree.world_array()
        return worlds

    def _measure(self, poses: Sequence[Mapping[str, float]]) -> tuple[Array, Array, Array]:
        """Per pose: capsule-pair gaps, capsule-box gaps and the arm's heights above the ground."""
        if not hasattr(self, "_capsule_link"):
            self._prepare()
        count = len(poses)
        worlds = self._worlds(poses)
        frames = worlds[:, self._capsule_link]  # (P, C, 4, 4)
        rotations, origins = frames[..., :3, :3], frames[..., :3, 3]
        starts = np.einsum("pcij,cj->pci", rotations, self._capsule_start) + origins
        ends = np.einsum("pcij,cj->pci", rotations, self._capsule_end) + origins
        radii = self._radii
        capsule_d = np.zeros((count, 0))
        if self._ci.size:
            ci, cj = self._ci, self._cj
            capsule_d = (
                segment_distances(
                    starts[:, ci].reshape(-1, 3),
                    ends[:, ci].reshape(-1, 3),
                    starts[:, cj].reshape(-1, 3),
                    ends[:, cj].reshape(-1, 3),
                ).reshape(count, -1)
                - radii[ci]
                - radii[cj]
            )
        box_d = np.zeros((count, 0))
        if self._bi.size:
            boxes = worlds[:, self._box_link] @ self._box_pose  # (P, B, 4, 4)
            box_rotations, box_origins = boxes[..., :3, :3], boxes[..., :3, 3]
            local_start = np.einsum(
                "pnji,pnj->pni", box_rotations, starts[:, self._bi] - box_origins
            )
            local_end = np.einsum("pnji,pnj->pni", box_rotations, ends[:, self._bi] - box_origins)
            halves = np.broadcast_to(self._box_half, local_start.shape)
            box_d = (
                segment_box_distances(
                    local_start.reshape(-1, 3), local_end.reshape(-1, 3), halves.reshape(-1, 3)
                ).reshape(count, -1)
                - radii[self._bi]
            )
        ground = np.zeros((count, 0))
        if self.ground_z_m is not None and self._ground_index.size:
            g = self._ground_index
            ground = np.minimum(starts[:, g, 2], ends[:, g, 2]) - radii[g] - self.ground_z_m
        return capsule_d, box_d, ground

    def _distances(self, angles: Mapping[str, float]) -> tuple[Array, Array]:
        capsule_d, box_d, _ = self._measure([angles])
        return capsule_d[0], box_d[0]

    def gaps_along(self, poses: Sequence[Mapping[str, float]]) -> Array:
        """(poses, pairs): every checked pair's gap in each pose (the ground's columns last);
        `pair_contact` names a column."""
        capsule_d, box_d, ground = self._measure(poses)
        return np.concatenate([capsule_d, box_d, ground], axis=1)

    def pair_contact(self, column: int, distance_m: float) -> Contact:
        """The two links of one column of `gaps_along`, at a gap."""
        capsule_count, box_count = len(self._capsule_pairs), len(self._box_pairs)
        if column < capsule_count:
            i, j = self._capsule_pairs[column]
            return Contact(distance_m, self.capsules[i].link, self.capsules[j].link)
        if column < capsule_count + box_count:
            i, j = self._box_pairs[column - capsule_count]
            return Contact(distance_m, self.capsules[i].link, self.boxes[j].link)
        index = self._ground[column - capsule_count - box_count]
        return Contact(distance_m, self.capsules[index].link, GROUND)

    def _contact(self, gaps: Array) -> Contact | None:
        if not gaps.size:
            return None
        column = int(np.argmin(gaps))
        return self.pair_contact(column, float(gaps[column]))

    def closest(self, angles: Mapping[str, float]) -> Contact | None:
        """The closest checked pair (or the ground) in a pose; None when nothing is checked."""
        return self._contact(self.gaps_along([angles])[0])

    def closest_along(self, poses: Sequence[Mapping[str, float]]) -> list[Contact | None]:
        """`closest` for many poses at once (a path), in one batched computation."""
        if not poses:
            return []
        gaps = self.gaps_along(poses)
        return [self._contact(row) for row in gaps]


def path_violation(gaps: Array, clearance_m: float) -> tuple[int, int] | None:
    """The first pose along a path, and its pair, that breaks the clearance rule; else None.

    `gaps` is (poses, pairs), the first pose where the path starts. Every pair keeps the
    clearance, except one already closer at the start: it may not come closer than it was
    (as MoveIt Servo lets a jog leave a collision) until it has cleared, then it keeps the
    clearance too. The arm can thus always be moved out of a pose it was left in too close.
    """
    if not gaps.size:
        return None
    start = gaps[0]
    cleared = np.logical_or.accumulate(gaps >= clearance_m, axis=0)
    floor = np.where(cleared, clearance_m, np.minimum(start, clearance_m) - SAME_GAP_M)
    bad = gaps < floor
    rows = np.flatnonzero(bad.any(axis=1))
    if not rows.size:
        return None
    row = int(rows[0])
    columns = np.flatnonzero(bad[row])
    return row, int(columns[np.argmin(gaps[row, columns])])


def _path_joints(tree: KinematicTree, a: str, b: str) -> list[str]:
    """Joint names on the tree path between two links."""

    def up(link: str) -> list[tuple[str, str]]:
        """(link, the joint above it) from a link up to the root."""
        steps = []
        while (joint := tree.parent_joint(link)) is not None:
            steps.append((link, joint.name))
            link = joint.parent
        steps.append((link, ""))
        return steps

    above_a, above_b = up(a), up(b)
    links_b = {link for link, _ in above_b}
    common = next(link for link, _ in above_a if link in links_b)
    joints: list[str] = []
    for steps in (above_a, above_b):
        for link, joint in steps:
            if link == common:
                break
            joints.append(joint)
    return joints
