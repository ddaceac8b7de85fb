"""Odometry: commands after the link delay, measured track speeds, the IMU, uncertainty."""

from __future__ import annotations

import math

import pytest

from ocu.nav.geometry import Pose
from ocu.nav.odometry import FROM_COMMANDS, FROM_TRACKS, STOPPED, Odometry
from ocu.profile import OdometrySettings, RobotProfile

SETTINGS = OdometrySettings()
TRACK_WIDTH_M = 0.5


def odometry(round_trip_s: float = 0.2) -> Odometry:
    odo = Odometry(TRACK_WIDTH_M, SETTINGS, min_linear_m_s=0.2, min_angular_rad_s=0.2)
    odo.set_round_trip(round_trip_s)
    return odo


def drive(odo: Odometry, v: float, w: float, start_s: float, end_s: float) -> None:
    """Commands repeated at 5 Hz, as the link sends them."""
    t = start_s
    while t < end_s - 1e-9:
        odo.on_command(t, v, w)
        t += 0.2


def test_commands_act_one_way_delay_after_they_were_sent() -> None:
    odo = odometry(round_trip_s=0.4)
    drive(odo, 0.3, 0.0, 0.0, 10.0)
    assert odo.estimate(0.2).pose.x_m == 0.0  # still on its way
    estimate = odo.estimate(5.2)
    assert estimate.pose.x_m == pytest.approx(1.5)
    assert estimate.source == FROM_COMMANDS
    assert estimate.stale  # nothing measured: only what was sent


def test_the_deadband_and_the_watchdog_are_the_robots() -> None:
    odo = odometry(round_trip_s=0.0)
    drive(odo, 0.1, 0.0, 0.0, 2.0)  # below the servos' starting speed
    assert odo.estimate(2.0).pose.x_m == 0.0
    odo.on_command(2.0, 0.3, 0.0)  # one command, then silence: the robot's 1 s watchdog
    assert odo.estimate(10.0).pose.x_m == pytest.approx(0.3)
    assert odo.estimate(10.0).source == STOPPED


def test_a_measured_stall_rewrites_the_commanded_motion() -> None:
    odo = odometry(round_trip_s=0.2)
    drive(odo, 0.3, 0.0, 0.0, 6.0)
    # Telemetry says the tracks stood still when it was taken (0.1 s before it arrived):
    # the robot hit something; the commands after that moved nothing.
    odo.on_tracks(3.1, 0.0, 0.0)
    odo.on_tracks(5.1, 0.0, 0.0)
    estimate = odo.estimate(5.1)
    assert estimate.pose.x_m == pytest.approx(0.3 * (3.0 - 0.1), abs=1e-9)
    assert estimate.source == STOPPED
    assert not estimate.stale


def test_measured_speeds_hold_until_the_next_command_acts() -> None:
    odo = odometry(round_trip_s=0.2)
    odo.on_command(0.0, 0.3, 0.0)
    # The robot really drives 0.25 m/s (track slip); the reading arrives at 0.6 s.
    odo.on_tracks(0.6, 0.25, 0.25)
    assert odo.estimate(1.0).pose.x_m == pytest.approx(0.3 * 0.4 + 0.25 * 0.5)
    assert odo.estimate(1.0).source == FROM_TRACKS
    odo.on_command(1.0, 0.0, 0.0)
    assert odo.estimate(3.0).pose.x_m == pytest.approx(0.3 * 0.4 + 0.25 * 0.6)


def test_turning_on_the_tracks_and_the_imu_heading() -> None:
    odo = odometry(round_trip_s=0.0)
    drive(odo, 0.0, 0.5, 0.0, 2.0)
    assert odo.estimate(2.0).pose.heading_rad == pytest.approx(1.0)
    # The IMU says the first heading was 1.0 rad: that is our frame's 1.0 rad.
    odo.on_heading(2.0, 3.0)
    # It really turned more slowly (track slip): the IMU's heading wins.
    odo.on_heading(2.4, 3.1)
    estimate = odo.estimate(2.4)
    assert estimate.pose.heading_rad == pytest.approx(1.1)
    assert estimate.heading_measured
    assert estimate.sigma_heading_rad <= SETTINGS.imu_heading_sigma_rad + 1e-12


def test_uncertainty_grows_with_distance_and_more_for_commands() -> None:
    commanded, measured = odometry(0.0), odometry(0.0)
    for odo in (commanded, measured):
        drive(odo, 0.3, 0.0, 0.0, 20.0)
    for t in range(1, 21):
        measured.on_tracks(float(t), 0.3, 0.3)
    near, far = commanded.estimate(5.0), commanded.estimate(20.0)
    assert 0.0 < near.sigma_xy_m < far.sigma_xy_m
    assert measured.estimate(20.0).sigma_xy_m < far.sigma_xy_m
    assert far.distance_m == pytest.approx(6.0)


def test_reset_starts_over_and_the_imu_zero_follows_it() -> None:
    odo = odometry(0.0)
    drive(odo, 0.3, 0.3, 0.0, 4.0)
    odo.on_heading(4.0, -2.0)
    odo.reset(4.0)
    estimate = odo.estimate(4.0)
    assert estimate.pose == Pose(0.0, 0.0, 0.0)
    assert estimate.sigma_xy_m == 0.0
    odo.on_heading(4.2, -1.9)  # the next heading is the new zero
    odo.on_heading(4.4, -1.8)
    assert odo.estimate(4.4).pose.heading_rad == pytest.approx(0.1)


def test_the_profile_holds_the_settings(profile: RobotProfile) -> None:
    settings = profile.navigation.odometry
    assert settings.stale_after_s == 2.5
    assert settings.imu_heading_sigma_rad == pytest.approx(math.radians(0.5))


def test_a_replay_at_four_times_covers_four_robot_seconds_per_second() -> None:
    odo = odometry(round_trip_s=0.0)
    odo.time_scale = 4.0
    drive(odo, 0.3, 0.0, 0.0, 1.0)  # the recording's commands, played four times as fast
    assert odo.estimate(1.0).pose.x_m == pytest.approx(1.2)


def test_the_estimate_reuses_past_segments_only_while_they_are_unchanged() -> None:
    """Estimates reuse the integration of complete segments; whatever arrives in between
    (commands, track speeds, headings, a new round trip, replay speed, a reset) gives the
    same estimate as integrating everything again."""
    import random

    rng = random.Random(3)
    odo = odometry()
    t = tracks_at = 0.0
    for _ in range(1500):
        t += rng.uniform(0.005, 0.08)
        r = rng.random()
        if r < 0.1:
            odo.on_command(t, rng.uniform(-0.4, 0.4), rng.uniform(-0.8, 0.8))
        elif r < 0.4:
            odo.on_tracks(t, rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3))
            tracks_at = t
        elif r < 0.5:
            odo.on_heading(t, rng.uniform(-3.0, 3.0))
        elif r < 0.55:
            # The IMU's reading of the moment the last track speeds were taken, late: it
            # changes a segment that may have been integrated already.
            odo.on_heading(tracks_at, rng.uniform(-3.0, 3.0))
        elif r < 0.57:
            odo.set_round_trip(rng.uniform(0.0, 0.4))
        elif r < 0.575:
            odo.time_scale = rng.choice((1.0, 4.0))
        elif r < 0.578:
            odo.reset(t)
        at = t + rng.uniform(-0.05, 0.3)
        cached = odo.estimate(at)
        odo._cache.clear()
        fresh = odo.estimate(at)
        assert cached.pose == fresh.pose
        assert cached.distance_m == fresh.distance_m
        assert (cached.covariance == fresh.covariance).all()
