"""The round-trip delay measured from echoed speed commands (pure, synthetic wire)."""

from __future__ import annotations

import random

import pytest

from ocu.link.delay import DelayEstimator

SEND_PERIOD_S = 0.05
TELEMETRY_PERIOD_S = 0.1


def simulate(
    estimator: DelayEstimator,
    *,
    uplink_s: float,
    downlink_s: float,
    jitter_s: float = 0.0,
    rcp_loss: float = 0.0,
    duration_s: float = 6.0,
    seed: int = 1,
) -> list[tuple[float, float | None]]:
    """A robot that echoes the latest command it received; (true delay, measured) per packet.

    The OCU changes one joint's speed on every send, as position control does.
    """
    rng = random.Random(seed)
    sent: list[tuple[float, int]] = []
    arrivals: list[tuple[float, int]] = []  # (arrival at the robot, value)
    t = 0.0
    value = 0
    while t < duration_s:
        value = int(300 * (1 + (t * 7) % 3)) if t > 1.0 else 0
        sent.append((t, value))
        if rng.random() >= rcp_loss:
            arrivals.append((t + uplink_s + rng.uniform(0, jitter_s), value))
        t += SEND_PERIOD_S
    arrivals.sort()
    out: list[tuple[float, float | None]] = []
    sends = iter(sent)
    pending = next(sends, None)
    taken = TELEMETRY_PERIOD_S
    while taken < duration_s:
        echo = max((a for a in arrivals if a[0] <= taken), default=(0.0, 0))[1]
        received = taken + downlink_s + rng.uniform(0, jitter_s)
        while pending is not None and pending[0] <= received:
            estimator.on_sent(pending[0], {5: pending[1]})
            pending = next(sends, None)
        true_delay = received - taken + uplink_s
        out.append((true_delay, estimator.on_telemetry(received, {5: echo})))
        taken += TELEMETRY_PERIOD_S
    return out


@pytest.mark.parametrize(("uplink_s", "downlink_s"), [(0.0, 0.0), (0.1, 0.1), (0.2, 0.15)])
def test_a_fixed_delay_is_measured(uplink_s: float, downlink_s: float) -> None:
    estimator = DelayEstimator()
    results = simulate(estimator, uplink_s=uplink_s, downlink_s=downlink_s)
    assert estimator.estimate_s == pytest.approx(uplink_s + downlink_s, abs=0.03)
    late = [(truth, measured) for truth, measured in results[-20:] if measured is not None]
    assert late
    for truth, measured in late:
        assert measured == pytest.approx(truth, abs=SEND_PERIOD_S)


def test_nothing_is_known_before_anything_moves() -> None:
    estimator = DelayEstimator()
    estimator.on_sent(0.0, {5: 0})
    assert estimator.on_telemetry(0.5, {5: 0}) is None
    assert estimator.estimate_s is None


def test_jitter_and_lost_commands_stay_near_the_truth() -> None:
    estimator = DelayEstimator()
    simulate(estimator, uplink_s=0.1, downlink_s=0.1, jitter_s=0.04, rcp_loss=0.1, seed=5)
    assert estimator.estimate_s is not None
    assert 0.19 <= estimator.estimate_s <= 0.3


def test_a_robot_that_echoes_something_else_teaches_nothing() -> None:
    estimator = DelayEstimator()
    for k in range(40):
        estimator.on_sent(k * 0.05, {5: 100 + k})
        if k % 2:
            assert estimator.on_telemetry(k * 0.05 + 0.01, {5: 7}) is None
    assert estimator.estimate_s is None
    assert estimator.inconsistent > 0
