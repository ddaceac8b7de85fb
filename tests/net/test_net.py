"""The select loop and the transports: real sockets, a real thread, deadlines not sleeps."""

from __future__ import annotations

import threading

import pytest

from ocu.net.loop import SelectLoop
from ocu.net.transport import (
    VIRTUAL_OCU,
    VIRTUAL_ROBOT,
    UdpTransport,
    VirtualWire,
)


def test_udp_transports_exchange_datagrams() -> None:
    a, b = UdpTransport(("127.0.0.1", 0)), UdpTransport(("127.0.0.1", 0))
    try:
        buffer = bytearray(2048)
        assert a.receive(buffer) is None
        b.send(b"hello", a.address)
        loop = SelectLoop("ocu-test-loop")
        got: list[bytes] = []
        done = threading.Event()

        def read() -> None:
            while (item := a.receive(buffer)) is not None:
                size, source = item
                assert source == b.address
                got.append(bytes(buffer[:size]))
                done.set()

        loop.add_reader(a.socket, read)
        loop.start(lambda now: now + 1.0)
        assert done.wait(2.0)
        assert loop.stop()
        loop.close()
        assert got == [b"hello"]
    finally:
        a.close()
        b.close()


def test_a_virtual_wire_connects_its_two_ends() -> None:
    wire = VirtualWire()
    try:
        buffer = bytearray(70_000)
        wire.ocu.send(b"x" * 60_000, VIRTUAL_ROBOT)  # a video frame's size
        item = wire.robot.receive(buffer)
        assert item == (60_000, VIRTUAL_OCU)
        wire.robot.send(b"telemetry", VIRTUAL_OCU)
        assert wire.ocu.receive(buffer) == (9, VIRTUAL_ROBOT)
        with pytest.raises(OSError, match="wired to"):
            wire.ocu.send(b"?", ("127.0.0.1", 10000))
    finally:
        wire.close()


def test_wake_cuts_a_wait_short_and_errors_are_the_owners_choice() -> None:
    steps: list[float] = []
    woken = threading.Event()

    def step(now: float) -> float:
        steps.append(now)
        if len(steps) == 2:
            woken.set()
        return now + 60.0  # nothing due for a minute

    loop = SelectLoop("ocu-test-wake")
    loop.start(step)
    loop.wake()
    assert woken.wait(2.0)
    assert loop.stop()
    loop.close()

    errors: list[BaseException] = []

    def count(err: BaseException) -> bool:
        errors.append(err)
        return True  # go on

    failing = SelectLoop("ocu-test-errors", on_error=count)
    calls = iter(range(1000))

    def bad_step(now: float) -> float:
        if next(calls) < 3:
            raise RuntimeError("one bad step")
        failing.stop()
        return now

    failing.run(bad_step)
    failing.close()
    assert len(errors) == 3
    raising = SelectLoop("ocu-test-raise")
    with pytest.raises(ZeroDivisionError):
        raising.run(lambda now: 1 / 0)
    raising.close()
