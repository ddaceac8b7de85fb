"""The calibration's least-squares fits, without a robot."""

from __future__ import annotations

import random

import pytest

from ocu.calibrate.fit import FitError, Run, fit_through_origin, fit_ticks_per_rad


def runs_of(ticks_per_rad: float, noise_ticks: float, seed: int = 1) -> list[Run]:
    """Runs of a joint at +-0.1 rad/s, readings every 0.1 s, from different origins."""
    rng = random.Random(seed)
    runs = []
    for index, speed in enumerate((0.1, -0.1, 0.1, -0.1)):
        times = tuple(10.0 * index + 0.1 * k for k in range(8))
        origin = 1000.0 * index
        positions = tuple(
            origin + ticks_per_rad * speed * (t - times[0]) + rng.uniform(-noise_ticks, noise_ticks)
            for t in times
        )
        runs.append(Run(times, positions, speed))
    return runs


def test_ticks_per_rad_from_exact_runs() -> None:
    fit = fit_ticks_per_rad(runs_of(7321.5, 0.0))
    assert fit.value == pytest.approx(7321.5, rel=1e-9)
    assert fit.residual == pytest.approx(0.0, abs=1e-6)
    assert fit.samples == 32


def test_noisy_runs_report_an_error_that_covers_the_truth() -> None:
    for seed in range(20):
        fit = fit_ticks_per_rad(runs_of(10_000.0, noise_ticks=60.0, seed=seed))
        assert fit.std_error is not None
        assert abs(fit.value - 10_000.0) < 4 * fit.std_error
        assert 20.0 < fit.residual < 60.0  # uniform noise of +-60: RMS about 35


def test_a_position_counting_against_the_speed_gives_a_negative_slope() -> None:
    reversed_runs = [
        Run(r.times_s, tuple(-p for p in r.positions), r.speed_rad_s) for r in runs_of(5000.0, 0.0)
    ]
    assert fit_ticks_per_rad(reversed_runs).value == pytest.approx(-5000.0)


def test_runs_of_one_reading_tell_nothing() -> None:
    with pytest.raises(FitError, match="two samples"):
        fit_ticks_per_rad([Run((1.0,), (5.0,), 0.1), Run((2.0, 3.0), (1.0, 2.0), 0.0)])


def test_through_origin_is_seed_000s_least_squares() -> None:
    # Axis values against measured speeds: the slope is the SI constant.
    speeds = [0.25, 0.30, 0.35]
    values = [71553.837 * v for v in speeds]
    fit = fit_through_origin(speeds, values, "axis")
    assert fit.value == pytest.approx(71553.837)
    assert fit.residual == pytest.approx(0.0, abs=1e-6)
    noisy = fit_through_origin(speeds, [values[0] + 100, values[1] - 100, values[2]], "axis")
    assert noisy.residual > 50
    assert noisy.std_error is not None
    with pytest.raises(FitError):
        fit_through_origin([0.0], [1.0], "axis")
