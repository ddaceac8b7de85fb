"""Samson's controller (seed 002, eq. 3.17-3.18), its references and the assisted modes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ocu.control.drive import DriveBounds, scale_drive
from ocu.nav.assist import AssistError, LinearShuttle, PathFollower
from ocu.nav.geometry import Pose, advance
from ocu.nav.grid import OccupancyGrid
from ocu.nav.tracking import Reference, along_path, ellipse, samson, samson_gains
from ocu.nav.world import load_world
from ocu.profile import AssistSettings
from ocu.protocol.mapping import scan_frame
from ocu.sim.rangefinder import RangeSensor

ASSIST = AssistSettings()
# The Engineer's drive: maxima 0.3 m/s and 0.8 rad/s, servos start at 0.2 (eq. 5.1-5.4).
BOUNDS = DriveBounds(0.3, 0.8, 0.2, 0.2)
DT_S = 0.05


def run(follower: PathFollower, pose: Pose, limit_s: float = 90.0) -> tuple[Pose, float, str]:
    """A unicycle driven by the follower through the drive's bounds; the end and its time."""
    t = 0.0
    while t < limit_s:
        command = follower.step(pose, t)
        if command.done:
            return pose, t, command.message
        v, w = scale_drive(command.linear_m_s, command.angular_rad_s, BOUNDS)
        pose = advance(pose, v * DT_S, w * DT_S)
        t += DT_S
    raise AssertionError("the follower never finished")


def test_gains_are_eq_3_18() -> None:
    k1, k2, k3 = samson_gains(0.2, 0.1, b=40.0, xi=0.8)
    assert k1 == k3 == pytest.approx(2 * 0.8 * math.sqrt(0.1**2 + 40 * 0.2**2))
    assert k2 == pytest.approx(40 * 0.2)


def test_the_controller_corrects_each_error_the_right_way() -> None:
    reference = Reference(0.0, 0.0, 0.0, 0.2, 0.0)
    behind = samson(Pose(-0.1, 0.0, 0.0), reference, 40.0, 0.8)
    assert behind[0] > 0.2
    assert behind[1] == pytest.approx(0.0)
    right_of_path = samson(Pose(0.0, -0.1, 0.0), reference, 40.0, 0.8)
    assert right_of_path[1] > 0.0  # turn left toward it
    # A heading just across ±π is a small error, not a full turn (the thesis' 360°/0° slip).
    across = Reference(0.0, 0.0, math.pi - 0.01, 0.2, 0.0)
    v, w = samson(Pose(0.0, 0.0, -math.pi + 0.01), across, 40.0, 0.8)
    assert abs(w) < 0.1
    assert v > 0.19


def test_the_ellipse_of_eq_6_1_takes_40_s_and_starts_at_the_robot() -> None:
    start = Pose(1.0, -2.0, 0.7)
    trajectory = ellipse(start)
    assert trajectory.duration_s == pytest.approx(40.0)
    first = trajectory.at(0.0)
    assert (first.x_m, first.y_m, first.heading_rad) == pytest.approx(tuple(start), abs=0.01)
    # Semi-axes 1.8 m and 1 m: its length is about 8.98 m.
    assert trajectory.length_m() == pytest.approx(8.98, abs=0.02)


@pytest.mark.parametrize("offset", [Pose(0.0, 0.0, 0.0), Pose(0.15, -0.1, 0.3)])
def test_following_the_ellipse_within_the_drives_bounds(offset: Pose) -> None:
    trajectory = ellipse(Pose(0.0, 0.0, 0.0))
    follower = PathFollower(trajectory, ASSIST, 0.0)
    end, time_s, message = run(follower, offset)
    assert "path done" in message
    assert time_s < 45.0
    assert math.hypot(end.x_m, end.y_m) <= ASSIST.goal_tolerance_m


def test_the_reference_waits_for_a_robot_that_cannot_move() -> None:
    follower = PathFollower(along_path(np.array([[0.0, 0.0], [3.0, 0.0]]), 0.25), ASSIST, 0.0)
    stuck = Pose(0.0, 0.0, 0.0)
    for k in range(200):
        follower.step(stuck, k * DT_S)
    # 10 s passed; the reference went on only until it was max_lag_m ahead.
    assert follower.trajectory.at(follower.reference_s).x_m <= ASSIST.max_lag_m + 0.05
    assert follower.waited_s > 5.0


def test_waypoints_are_followed_round_corners() -> None:
    path = along_path(np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]]), 0.25)
    end, _time_s, message = run(PathFollower(path, ASSIST, 0.0), Pose(0.0, 0.0, 0.0))
    assert "path done" in message
    assert math.hypot(end.x_m, end.y_m - 2.0) <= ASSIST.goal_tolerance_m


def test_linear_shuttle_eq_5_5_and_its_turnarounds() -> None:
    shuttle = LinearShuttle(
        (0.0, 0.0),
        (3.0, 0.0),
        Pose(0.0, 0.0, 0.0),
        ASSIST,
        max_linear_m_s=0.45,
        min_linear_m_s=0.2,
        cycles=1,
    )
    # 3 m from its goal: sqrt(3 * 0.05) = 0.387 m/s (the thesis' sqrt(3000 * 50) mm/s).
    assert shuttle.step(Pose(0.0, 0.0, 0.0), 0.0).linear_m_s == pytest.approx(math.sqrt(0.15))
    assert shuttle.step(Pose(2.9, 0.0, 0.0), 1.0).linear_m_s == pytest.approx(0.2)  # clamped
    assert shuttle.step(Pose(3.01, 0.0, 0.0), 2.0).linear_m_s < 0.0  # turned round
    assert shuttle.step(Pose(-0.01, 0.0, 0.0), 3.0).done  # one shuttle there and back
    with pytest.raises(AssistError, match="faces 90° away"):
        LinearShuttle(
            (0.0, 0.0),
            (3.0, 0.0),
            Pose(0.0, 0.0, math.pi / 2),
            ASSIST,
            max_linear_m_s=0.45,
            min_linear_m_s=0.2,
        )


def test_the_grid_marks_walls_occupied_and_the_room_free() -> None:
    world = load_world("default")
    sensor = RangeSensor(world, seed=3)
    grid = OccupancyGrid()
    for pose in (Pose(0.0, 0.0, 0.0), Pose(1.0, -1.0, 1.0)):
        scan = scan_frame(sensor.sweep(pose, 0), 0.0, 0.0)
        for _ in range(4):
            grid.integrate(scan, pose, (0.0, 0.0))

    def at(x: float, y: float) -> float:
        """The most occupied cell within a cell of (x, y) (the range noise spreads hits)."""
        row, column, inside = grid.cell_of(np.array([x]), np.array([y]))
        assert inside[0]
        r, c = row[0], column[0]
        near = grid.probabilities()[r - 1 : r + 2, c - 1 : c + 2]
        return float(near.max() if near.max() > 0.5 else near.min())

    assert at(0.5, 0.5) < 0.2  # open floor
    assert at(4.95, 0.0) > 0.8  # the east wall's face
    assert at(8.0, 8.0) == pytest.approx(0.5)  # never seen
    grid.clear()
    assert at(4.95, 0.0) == pytest.approx(0.5)
