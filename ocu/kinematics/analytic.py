"""Geometric inverse kinematics of a yaw joint plus three parallel pitch joints (seed 003 §2.3).

The Engineer's waist turns the arm about a vertical axis; its shoulder, elbow and neck pitch
it in one vertical plane. Given tool0's position (x, y, z) and its pitch α (the angle of its x
axis from the outward horizontal in the arm's plane, positive up), seed 003's construction
solves it in closed form: the waist from the azimuth of the target; in the arm's plane, the
wrist point (the last pitch axis) is the target minus the tool offset turned by α; the
shoulder and elbow follow from the triangle shoulder-elbow-wrist by the cosine rule
(elbow-up and elbow-down); the neck makes up the pitch.

Nothing here is the Engineer's by name: the geometry (lengths, offsets, axis signs, which way
the arm points at zero) is read off the chain in its zero pose, so any arm of this structure
works; `YawPitchArm` refuses a chain that does not have it. Besides the usual front branch
the arm may reach over its top (a shoulder beyond 90°): the "back" branch, with the tool still
measured outward from the waist axis, is tried when the front one is out of the joints' limits.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ocu.kinematics.chain import Chain, ChainError, Vector

PARALLEL_TOLERANCE = 1e-6
PLANAR_TOLERANCE_M = 1e-6
# A target this close to the yaw axis leaves the yaw free: the current one is kept.
ON_AXIS_M = 1e-6
ELBOW_UP = "elbow up"
ELBOW_DOWN = "elbow down"
BRANCHES = (ELBOW_UP, ELBOW_DOWN)


class UnreachableError(ValueError):
    """No joint values put the tool there; the message says why."""


@dataclass(frozen=True)
class AnalyticSolution:
    """Joint values (chain order: yaw, then the pitch joints) and which branch they are."""

    q: Vector
    elbow: str
    over_the_top: bool


def _wrap(angle: float) -> float:
    return math.atan2(math.sin(angle), math.cos(angle))


def _rotate(angle: float, u: float, w: float) -> tuple[float, float]:
    c, s = math.cos(angle), math.sin(angle)
    return c * u - s * w, s * u + c * w


class YawPitchArm:
    """Closed-form IK of a yaw + three-pitch chain; see the module docstring."""

    def __init__(self, chain: Chain) -> None:
        if chain.dof != 4:
            raise ChainError(
                f"a yaw + three pitch arm has 4 joints; {chain.base} -> {chain.tip} has "
                f"{chain.dof} ({', '.join(chain.joints)})"
            )
        if np.any(chain.prismatic):
            raise ChainError("a yaw + three pitch arm has revolute joints only")
        self.chain = chain
        zero = np.zeros(4)
        axes, tool = chain.axes(zero)
        (yaw_point, yaw_axis), *pitch = axes
        up = np.array([0.0, 0.0, 1.0])
        yaw_dot = float(yaw_axis @ up)
        if abs(abs(yaw_dot) - 1.0) > PARALLEL_TOLERANCE:
            raise ChainError(f"{chain.joints[0]}: the yaw axis is not vertical in {chain.base}")
        self.yaw_sign = 1.0 if yaw_dot > 0 else -1.0
        lateral_axis = pitch[0][1]
        for name, (_, axis) in zip(chain.joints[1:], pitch, strict=True):
            if abs(abs(float(axis @ lateral_axis)) - 1.0) > PARALLEL_TOLERANCE:
                raise ChainError(f"{name}: its axis is not parallel to {chain.joints[1]}'s")
            if abs(float(axis @ up)) > PARALLEL_TOLERANCE:
                raise ChainError(f"{name}: a pitch axis must be horizontal")
        # The arm's plane at yaw 0: u points where the arm reaches, w up, y to its left.
        reach = tool[:3, 3] - pitch[0][0]
        outward = reach - (reach @ lateral_axis) * lateral_axis
        outward[2] = 0.0
        if np.linalg.norm(outward) < PLANAR_TOLERANCE_M:
            outward = np.cross(lateral_axis, up)
        self.outward = outward / np.linalg.norm(outward)
        self.lateral = np.cross(up, self.outward)
        self.origin = yaw_point
        # Planar angles grow counter-clockwise in (u, w): a rotation about -y.
        self.signs = tuple(-float(axis @ self.lateral) for _, axis in pitch)
        points = [self._plane(p) for p, _ in pitch] + [self._plane(tool[:3, 3])]
        offsets = [d for _, _, d in points]
        if max(offsets) - min(offsets) > PLANAR_TOLERANCE_M:
            raise ChainError("the pitch joints and the tool do not lie in one plane")
        self.lateral_offset_m = offsets[0]
        (u1, w1, _), (u2, w2, _), (u3, w3, _), (ut, wt, _) = points
        self.shoulder = (u1, w1)
        self.upper_m = math.hypot(u2 - u1, w2 - w1)
        self.upper_angle = math.atan2(w2 - w1, u2 - u1)
        self.fore_m = math.hypot(u3 - u2, w3 - w2)
        self.fore_angle = math.atan2(w3 - w2, u3 - u2)
        self.tool_offset = (ut - u3, wt - w3)
        tool_x = tool[:3, 0]
        if abs(float(tool_x @ self.lateral)) > 1e-6:
            raise ChainError(f"{chain.tip}: its x axis does not lie in the arm's plane")
        self.tool_angle = math.atan2(float(tool_x @ up), float(tool_x @ self.outward))
        if self.upper_m < PLANAR_TOLERANCE_M or self.fore_m < PLANAR_TOLERANCE_M:
            raise ChainError("two pitch axes coincide")

    def plane_point(self, u: float, w: float) -> Vector:
        """The base-frame point at (u, w) in the arm's plane at yaw 0."""
        result: Vector = self.origin + self.outward * u + self.lateral * self.lateral_offset_m
        result[2] += w
        return result

    def _plane(self, point: Vector) -> tuple[float, float, float]:
        relative = point - self.origin
        return float(relative @ self.outward), float(relative[2]), float(relative @ self.lateral)

    @property
    def reach_m(self) -> float:
        """The farthest the wrist point (the last pitch axis) gets from the shoulder axis."""
        return self.upper_m + self.fore_m

    def solutions(
        self,
        position: Sequence[float],
        pitch_rad: float,
        current: Sequence[float] | Vector | None = None,
    ) -> tuple[list[AnalyticSolution], list[str]]:
        """Every solution within the joint limits, and why each other candidate failed."""
        x, y, z = (float(v) for v in position)
        if not all(math.isfinite(v) for v in (x, y, z, pitch_rad)):
            raise UnreachableError("the target must be finite")
        dx, dy = x - self.origin[0], y - self.origin[1]
        radius = math.hypot(dx, dy)
        offset = self.lateral_offset_m
        if radius < abs(offset) - PLANAR_TOLERANCE_M:
            raise UnreachableError(
                f"closer to the {self.chain.joints[0]} axis ({radius * 1000:.0f} mm) than the "
                f"arm's sideways offset ({abs(offset) * 1000:.0f} mm)"
            )
        along = math.sqrt(max(radius * radius - offset * offset, 0.0))
        current_yaw = float(current[0]) if current is not None else 0.0
        found: list[AnalyticSolution] = []
        reasons: list[str] = []
        for over_the_top in (False, True):
            u = -along if over_the_top else along
            if radius < ON_AXIS_M:
                yaw = current_yaw
            else:
                azimuth = math.atan2(dy, dx) - math.atan2(self.outward[1], self.outward[0])
                yaw = self.yaw_sign * _wrap(azimuth - math.atan2(offset, u))
            tool_plane = math.pi - pitch_rad if over_the_top else pitch_rad
            for solution, reason in self._plane_solutions(
                u, z - self.origin[2], tool_plane, yaw, over_the_top
            ):
                if solution is not None:
                    found.append(solution)
                elif reason not in reasons:
                    reasons.append(reason)
            if radius < ON_AXIS_M:
                break
        return found, reasons

    def _plane_solutions(
        self, u: float, w: float, tool_plane: float, yaw: float, over_the_top: bool
    ) -> list[tuple[AnalyticSolution | None, str]]:
        last = tool_plane - self.tool_angle
        tu, tw = _rotate(last, *self.tool_offset)
        wrist = (u - tu - self.shoulder[0], w - tw - self.shoulder[1])
        distance = math.hypot(*wrist)
        l1, l2 = self.upper_m, self.fore_m
        cosine = (distance * distance - l1 * l1 - l2 * l2) / (2.0 * l1 * l2)
        if cosine > 1.0 + 1e-12:
            return [
                (
                    None,
                    f"out of reach: the wrist point would be {distance * 1000:.0f} mm from the "
                    f"{self.chain.joints[1]} axis; the arm reaches {self.reach_m * 1000:.0f} mm",
                )
            ]
        if cosine < -1.0 - 1e-12:
            return [
                (
                    None,
                    f"too close: the wrist point would be {distance * 1000:.0f} mm from the "
                    f"{self.chain.joints[1]} axis; the arm folds to no less than "
                    f"{abs(l1 - l2) * 1000:.0f} mm",
                )
            ]
        bend = math.acos(min(max(cosine, -1.0), 1.0))
        results: list[tuple[AnalyticSolution | None, str]] = []
        for delta in (bend, -bend) if bend > 0.0 else (0.0,):
            first = math.atan2(wrist[1], wrist[0]) - math.atan2(
                l2 * math.sin(delta), l1 + l2 * math.cos(delta)
            )
            a1 = first - self.upper_angle
            a2 = first + delta - self.fore_angle
            s1, s2, s3 = self.signs
            q = np.array(
                [
                    _wrap(yaw),
                    _wrap(a1 / s1),
                    _wrap((a2 - a1) / s2),
                    _wrap((last - a2) / s3),
                ]
            )
            q = self._nearest_turn(q)
            # Elbow up: the elbow lies above the line from the shoulder to the wrist, seen
            # from the side the arm reaches to.
            elbow_u = l1 * math.cos(first)
            elbow_w = l1 * math.sin(first)
            cross = wrist[0] * elbow_w - wrist[1] * elbow_u
            facing = -1.0 if over_the_top else 1.0
            elbow = ELBOW_UP if cross * facing >= 0.0 else ELBOW_DOWN
            if bend == 0.0:
                for branch in BRANCHES:
                    results.append(self._checked(q, branch, over_the_top))
            else:
                results.append(self._checked(q, elbow, over_the_top))
        return results

    def _nearest_turn(self, q: Vector) -> Vector:
        """Joint values moved by whole turns into their limits where that is possible."""
        out = q.copy()
        for i in range(4):
            for turn in (0.0, 2.0 * math.pi, -2.0 * math.pi):
                value = q[i] + turn
                if self.chain.lower[i] <= value <= self.chain.upper[i]:
                    out[i] = value
                    break
        return out

    def _checked(
        self, q: Vector, elbow: str, over_the_top: bool
    ) -> tuple[AnalyticSolution | None, str]:
        for i, name in enumerate(self.chain.joints):
            low, high = self.chain.lower[i], self.chain.upper[i]
            if not low - 1e-9 <= q[i] <= high + 1e-9:
                where = "over the top, " if over_the_top else ""
                return (
                    None,
                    f"{where}{elbow}: {name} would need {math.degrees(q[i]):.1f}° "
                    f"(limits {math.degrees(low):.1f}° to {math.degrees(high):.1f}°)",
                )
        return AnalyticSolution(self.chain.clamp(q), elbow, over_the_top), ""

    def solve(
        self,
        position: Sequence[float],
        pitch_rad: float,
        *,
        elbow: str | None = None,
        current: Sequence[float] | Vector | None = None,
    ) -> AnalyticSolution:
        """The solution on the asked elbow branch (either if None) nearest to `current`.

        Without `current`, front-branch solutions win over reaching over the top. UnreachableError
        with the reasons when there is none.
        """
        if elbow is not None and elbow not in BRANCHES:
            raise ValueError(f"elbow must be one of {BRANCHES}, got {elbow!r}")
        found, reasons = self.solutions(position, pitch_rad, current)
        candidates = [s for s in found if elbow is None or s.elbow == elbow]
        if not candidates:
            if found:
                other = found[0].elbow
                raise UnreachableError(
                    f"no {elbow} solution within the joint limits (only {other})"
                )
            raise UnreachableError("; ".join(reasons) if reasons else "no solution")
        reference = np.zeros(4) if current is None else np.asarray(current, dtype=float)

        def cost(solution: AnalyticSolution) -> tuple[bool, float]:
            distance = float(np.sum(np.abs(solution.q - reference)))
            return (solution.over_the_top and current is None), distance

        return min(candidates, key=cost)
