"""The calibration's least-squares fits, without a robot."""

from __future__ import annotations

import math
import random

import pytest

from ocu.calibrate.fit import (
    FitError,
    Run,
    fit_through_origin,
    fit_ticks_per_rad,
    rounding_uncertainty,
)


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


def rounded_runs(rng: random.Random, ticks_per_rad: float, step: float) -> list[Run]:
    """Three sweeps (out, back twice as long, out) at 20 Hz with noisy readings, the speed
    reported rounded to `step`, as the simulator reports it."""
    true_speed = rng.uniform(0.04, 0.11)
    reported = round(true_speed / step) * step
    runs = []
    for index, (samples, sign) in enumerate(((22, 1), (44, -1), (22, 1))):
        times = tuple(10.0 * index + 0.05 * k for k in range(samples))
        positions = tuple(
            sign * ticks_per_rad * true_speed * (t - times[0]) + rng.uniform(-37.0, 37.0)
            for t in times
        )
        runs.append(Run(times, positions, sign * reported))
    return runs


def test_the_stated_uncertainty_covers_the_speeds_rounding() -> None:
    # The error the residuals cannot show: every run rests on one rounded speed. The
    # statistical error alone covered the truth in about half the trials (it printed
    # "±0.05 %" for errors of 0.3-0.8 %); the expanded uncertainty is stated at about 95 %.
    rng = random.Random(5)
    trials = 400
    covered = covered_by_statistics = 0
    for _ in range(trials):
        fit = fit_ticks_per_rad(rounded_runs(rng, 14_243.0, 0.001), speed_step_rad_s=0.001)
        error = abs(fit.value - 14_243.0) / 14_243.0
        assert fit.relative_error is not None
        assert fit.expanded_uncertainty is not None
        covered += error <= fit.expanded_uncertainty
        covered_by_statistics += error <= fit.relative_error  # what was printed
    assert covered >= 0.9 * trials
    assert covered_by_statistics < 0.7 * trials


def test_rounding_uncertainty_of_one_speed_and_of_several() -> None:
    one = fit_ticks_per_rad(runs_of(7000.0, 0.0), speed_step_rad_s=0.001)
    # 0.1 rad/s reported in steps of 0.001: a uniform error over ±0.5 of 100 steps.
    assert one.systematic == pytest.approx(1 / math.sqrt(12) / 100)
    assert one.uncertainty == pytest.approx(one.systematic, rel=1e-6)  # exact runs otherwise
    assert fit_ticks_per_rad(runs_of(7000.0, 0.0)).systematic == 0.0
    # Two speeds round independently: their shares add in quadrature.
    assert rounding_uncertainty([0.1, 0.2], [1.0, 1.0], 0.001) == pytest.approx(
        math.hypot(0.5 / 100, 0.5 / 200) / math.sqrt(12)
    )
    # An axis scale against a rounded speed: the residuals are zero, the rounding is not.
    scale = fit_through_origin([0.05, 0.05], [1000.0, 1000.0], "axis", x_step=0.001)
    assert scale.std_error == pytest.approx(0.0, abs=1e-9)
    assert scale.expanded_uncertainty == pytest.approx(2 / math.sqrt(12) / 50)
