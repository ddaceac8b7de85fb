"""Helpers of the recording tests: a collecting listener and readers built on mcap's own."""

from __future__ import annotations

import threading
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from ocu.records import (
    DatagramReceived,
    DatagramSent,
    LinkEvent,
    LinkState,
    LinkStateChanged,
    LinkStats,
    SafetyEvent,
    StatusFrame,
    TelemetryFrame,
    VideoFrame,
)

DEADLINE_S = 10.0


class Collector:
    """Keeps every event a link (or a replay) reports; tests wait on it with deadlines."""

    def __init__(self) -> None:
        self.cond = threading.Condition()
        self.sent: list[bytes] = []
        self.received: list[bytes] = []
        self.telemetry: list[TelemetryFrame] = []
        self.video: list[VideoFrame] = []
        self.status: list[StatusFrame] = []
        self.states: list[LinkState] = []
        self.stats: list[LinkStats] = []
        self.safety: list[str] = []
        self.finished = False

    def mark_finished(self) -> None:
        """A replay's on_finished: under the condition, so a wait on it wakes at once (a
        wait re-checks only when notified; the end may come after the last event)."""
        with self.cond:
            self.finished = True
            self.cond.notify_all()

    def __call__(self, event: LinkEvent) -> None:
        with self.cond:
            if isinstance(event, DatagramSent):
                self.sent.append(event.data)
            elif isinstance(event, DatagramReceived):
                self.received.append(event.data)
            elif isinstance(event, TelemetryFrame):
                self.telemetry.append(event)
            elif isinstance(event, VideoFrame):
                self.video.append(event)
            elif isinstance(event, StatusFrame):
                self.status.append(event)
            elif isinstance(event, LinkStateChanged):
                self.states.append(event.state)
            elif isinstance(event, LinkStats):
                self.stats.append(event)
            elif isinstance(event, SafetyEvent):
                self.safety.append(event.message)
            self.cond.notify_all()

    def wait(self, predicate: Callable[[], bool], timeout_s: float = DEADLINE_S) -> bool:
        with self.cond:
            return self.cond.wait_for(predicate, timeout_s)


def poll_until(predicate: Callable[[], bool], timeout_s: float = DEADLINE_S) -> bool:
    """Check a condition nothing signals (a file's size) until it holds or the deadline."""
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.02)
    return True


class Message:
    """One message read back: its times and decoded content."""

    def __init__(self, log_time: int, publish_time: int, decoded: Any) -> None:
        self.log_time = log_time
        self.publish_time = publish_time
        self.decoded = decoded


def read_finished(path: Path) -> tuple[dict[str, list[Message]], Any]:
    """Every message by topic, in file order, and the summary: mcap's seeking reader."""
    topics: dict[str, list[Message]] = defaultdict(list)
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        for _, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
            topics[channel.topic].append(Message(message.log_time, message.publish_time, decoded))
    return topics, summary


def assert_monotonic(topics: dict[str, list[Message]]) -> None:
    """Log times never go back within a channel."""
    for topic, messages in topics.items():
        times = [m.log_time for m in messages]
        assert times == sorted(times), f"{topic}: log times not monotonic"
