"""Inverse kinematics of any chain by damped least squares (Levenberg-Marquardt).

Each step solves (J Jᵀ + λ² I) y = e and moves by Jᵀ y: near a singularity the damping λ keeps
the step bounded instead of letting the pseudo-inverse explode. λ adapts: a step that lowers
the error is kept and λ shrinks; one that does not is undone and λ grows. Every step is clipped
to the joint limits. When one start does not converge the solver restarts from seeded random
joint values within the limits, so the answer is deterministic for a given seed.

`rows` picks the task: all six (position and orientation), the first three (position only),
or any subset, e.g. position plus one rotation about a fixed axis (`axis_rows`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ocu.kinematics.chain import Chain, Vector, rotation_error
from ocu.model.tree import Matrix

DEFAULT_TOLERANCE_M = 1e-5
DEFAULT_TOLERANCE_RAD = 1e-4
DEFAULT_ITERATIONS = 150
DEFAULT_RESTARTS = 12
INITIAL_DAMPING = 0.05
MIN_DAMPING = 1e-6
MAX_DAMPING = 10.0
# The largest joint change of one step (rad or m): keeps a far target from flinging joints.
MAX_STEP = 0.5
# Unbounded (continuous) joints restart within one turn either way.
UNBOUNDED_RANGE = math.pi


class IkError(ValueError):
    """No solution within the tolerance: the reason says how close the best try came."""


@dataclass(frozen=True)
class NumericSolution:
    """Joint values (chain order) and how far the tip is from the target."""

    q: Vector
    position_error_m: float
    orientation_error_rad: float
    iterations: int
    restarts: int


def _error(
    chain: Chain, q: Vector, target: Matrix, rows: Sequence[int], weights: Vector
) -> tuple[Vector, Matrix]:
    pose = chain.forward(q)
    full = np.concatenate([target[:3, 3] - pose[:3, 3], rotation_error(pose, target)])
    return full[list(rows)] * weights, pose


def solve(
    chain: Chain,
    target: Matrix,
    q0: Sequence[float] | Vector | None = None,
    *,
    rows: Sequence[int] = (0, 1, 2, 3, 4, 5),
    orientation_weight_m: float = 0.2,
    tolerance_m: float = DEFAULT_TOLERANCE_M,
    tolerance_rad: float = DEFAULT_TOLERANCE_RAD,
    max_iterations: int = DEFAULT_ITERATIONS,
    restarts: int = DEFAULT_RESTARTS,
    seed: int = 0,
) -> NumericSolution:
    """Joint values that put the chain's tip at `target` (a 4x4 pose in the base frame).

    `orientation_weight_m` converts radians to metres in the error norm (an angle error of
    1 rad weighs as much as this many metres of position error). IkError when no start
    converges; its message gives the best errors reached.
    """
    if chain.dof == 0:
        raise IkError(f"the chain {chain.base} -> {chain.tip} has no moving joint")
    if not np.all(np.isfinite(target)):
        raise IkError("the target pose must be finite")
    rows = tuple(rows)
    weights = np.array([1.0 if r < 3 else orientation_weight_m for r in rows])
    low = np.where(np.isfinite(chain.lower), chain.lower, -UNBOUNDED_RANGE)
    high = np.where(np.isfinite(chain.upper), chain.upper, UNBOUNDED_RANGE)
    rng = np.random.default_rng(seed)
    start = chain.clamp(np.zeros(chain.dof) if q0 is None else np.asarray(q0, dtype=float))
    best: tuple[float, float, Vector] | None = None
    iterations = 0
    for attempt in range(restarts + 1):
        q = start if attempt == 0 else rng.uniform(low, high)
        q, used, position_error, orientation_error = _descend(
            chain, target, q, rows=rows, weights=weights, max_iterations=max_iterations
        )
        iterations += used
        if best is None or position_error + orientation_error * orientation_weight_m < (
            best[0] + best[1] * orientation_weight_m
        ):
            best = (position_error, orientation_error, q)
        if position_error <= tolerance_m and orientation_error <= tolerance_rad:
            return NumericSolution(q, position_error, orientation_error, iterations, attempt)
    assert best is not None
    raise IkError(
        f"no solution within {tolerance_m * 1000:.2f} mm / {math.degrees(tolerance_rad):.3f}° "
        f"after {restarts + 1} starts; the closest was {best[0] * 1000:.1f} mm and "
        f"{math.degrees(best[1]):.2f}° off (out of reach, or beyond a joint limit)"
    )


def _descend(
    chain: Chain,
    target: Matrix,
    q: Vector,
    *,
    rows: tuple[int, ...],
    weights: Vector,
    max_iterations: int,
) -> tuple[Vector, int, float, float]:
    """Levenberg-Marquardt from one start; returns q and its position/orientation errors."""
    damping = INITIAL_DAMPING
    error, pose = _error(chain, q, target, rows, weights)
    cost = float(error @ error)
    used = 0
    for used in range(1, max_iterations + 1):  # noqa: B007 (counted after the loop)
        jac = chain.jacobian(q)[list(rows)] * weights[:, None]
        system = jac @ jac.T + damping**2 * np.eye(len(rows))
        step = jac.T @ np.linalg.solve(system, error)
        largest = float(np.max(np.abs(step))) if step.size else 0.0
        if largest > MAX_STEP:
            step *= MAX_STEP / largest
        candidate = chain.clamp(q + step)
        new_error, new_pose = _error(chain, candidate, target, rows, weights)
        new_cost = float(new_error @ new_error)
        if new_cost < cost:
            q, error, pose, cost = candidate, new_error, new_pose, new_cost
            damping = max(damping * 0.5, MIN_DAMPING)
        else:
            damping = min(damping * 4.0, MAX_DAMPING)
            if damping >= MAX_DAMPING and new_cost >= cost:
                break
        if cost < 1e-22:
            break
    full = np.concatenate([target[:3, 3] - pose[:3, 3], rotation_error(pose, target)])
    position = [r for r in rows if r < 3]
    rotation = [r for r in rows if r >= 3]
    position_error = float(np.linalg.norm(full[position])) if position else 0.0
    orientation_error = float(np.linalg.norm(full[rotation])) if rotation else 0.0
    return q, used, position_error, orientation_error


def damped_pseudo_inverse(jac: npt.NDArray[np.float64], damping: float) -> npt.NDArray[np.float64]:
    """Jᵀ (J Jᵀ + λ² I)⁻¹: the pseudo-inverse, bounded near singularities."""
    rows = jac.shape[0]
    result: npt.NDArray[np.float64] = jac.T @ np.linalg.inv(jac @ jac.T + damping**2 * np.eye(rows))
    return result
