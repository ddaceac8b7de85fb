"""Fault injection without sockets: seeded decisions, the delay line, the fault layer."""

from __future__ import annotations

import pytest

from ocu.sim.faults import DelayLine, Direction, FaultConfig, FaultLayer, make_injectors

OCU = ("127.0.0.1", 5000)
Delivered = list[tuple[Direction, bytes, tuple[str, int], float]]


def make_layer(config: FaultConfig) -> tuple[FaultLayer, Delivered]:
    """A fault layer that records what it delivers."""
    delivered: Delivered = []
    layer = FaultLayer(config, 3, lambda *datagram: delivered.append(datagram))
    return layer, delivered


def test_injector_decisions_are_seeded_and_bounded() -> None:
    config = FaultConfig(loss=0.2, latency_ms=100.0, jitter_ms=50.0, duplicate=0.1)
    first = make_injectors(42)[Direction.TO_ROBOT]
    second = make_injectors(42)[Direction.TO_ROBOT]
    plans = [first.plan(config) for _ in range(500)]
    assert plans == [second.plan(config) for _ in range(500)]
    delays_s = [delay_s for plan in plans for delay_s in plan]
    assert all(0.1 <= delay_s <= 0.15 for delay_s in delays_s)
    assert len(set(delays_s)) > 100
    assert any(len(plan) == 2 for plan in plans)
    assert any(not plan for plan in plans)
    to_ocu = make_injectors(42)[Direction.TO_OCU]
    assert [to_ocu.plan(config) for _ in range(500)] != plans
    assert make_injectors(1)[Direction.TO_OCU].plan(FaultConfig(loss=1.0)) == []


def test_delay_line_releases_in_due_order() -> None:
    line = DelayLine()
    address = ("127.0.0.1", 1)
    line.push(2.0, Direction.TO_OCU, b"late", address)
    line.push(1.0, Direction.TO_ROBOT, b"early", address)
    line.push(1.0, Direction.TO_ROBOT, b"early-second", address)
    assert line.next_due_s() == 1.0
    assert [d.data for d in line.pop_due(1.5)] == [b"early", b"early-second"]
    assert len(line) == 1
    assert line.pop_due(1.9) == []
    assert [d.data for d in line.pop_due(2.0)] == [b"late"]
    assert line.next_due_s() is None


def test_a_clean_layer_delivers_at_once() -> None:
    layer, delivered = make_layer(FaultConfig())
    layer.route(Direction.TO_ROBOT, b"rcp", OCU, 1.0)
    layer.route(Direction.TO_OCU, b"telemetry", OCU, 1.5)
    assert delivered == [
        (Direction.TO_ROBOT, b"rcp", OCU, 1.0),
        (Direction.TO_OCU, b"telemetry", OCU, 1.5),
    ]
    assert layer.next_due_s() == float("inf")
    assert (layer.dropped_to_robot, layer.dropped_to_ocu, layer.duplicated) == (0, 0, 0)


def test_latency_holds_datagrams_until_due_and_duplicates_count() -> None:
    layer, delivered = make_layer(FaultConfig(latency_ms=100.0, duplicate=1.0))
    layer.route(Direction.TO_OCU, b"frame", OCU, 1.0)
    assert delivered == []
    assert layer.next_due_s() == pytest.approx(1.1)
    layer.release_due(1.09)
    assert delivered == []
    layer.release_due(1.1)
    assert [d[1] for d in delivered] == [b"frame", b"frame"]
    assert delivered[0][3] == 1.1
    assert layer.duplicated == 1


def test_a_cut_drops_new_and_delayed_datagrams_both_ways() -> None:
    layer, delivered = make_layer(FaultConfig(latency_ms=50.0))
    layer.route(Direction.TO_OCU, b"in flight", OCU, 1.0)
    layer.set_cut(True)
    assert layer.cut
    layer.route(Direction.TO_ROBOT, b"rcp", OCU, 1.01)
    layer.release_due(2.0)
    assert delivered == []
    assert (layer.dropped_to_robot, layer.dropped_to_ocu) == (1, 1)
    layer.set_cut(False)
    layer.route(Direction.TO_ROBOT, b"rcp", OCU, 2.0)
    layer.release_due(2.05)
    assert [d[1] for d in delivered] == [b"rcp"]


def test_change_keeps_the_other_settings_and_validates() -> None:
    layer, _ = make_layer(FaultConfig(loss=0.1))
    assert layer.change(latency_ms=20.0) == FaultConfig(loss=0.1, latency_ms=20.0)
    assert layer.config == FaultConfig(loss=0.1, latency_ms=20.0)
    with pytest.raises(ValueError, match="duplicate"):
        layer.change(duplicate=2.0)
    assert layer.config.duplicate == 0.0
