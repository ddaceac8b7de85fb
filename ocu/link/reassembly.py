"""Bounded reassembly of extension video fragments into whole JPEG frames (pure, no I/O).

Partial frames are keyed by (camera, sequence) and held in arrival order. Memory is bounded
twice, by a number of partial frames and by the bytes they reserve; past either bound the
oldest partial frame is evicted. A partial frame older than the timeout expires. Per camera
only frames newer than the newest frame delivered are kept: an older one can never be shown,
so it is dropped and counted. Sequence numbers are compared modulo 2**32. A stream that
went back is a robot that restarted its counter (it rebooted) rather than a stale frame when
it jumped far backwards, or when the camera delivered nothing for the timeout before it (a
frame held up that long in the network is of no use anyway); `reset()` (LINK LOST) forgets
every camera's newest number at once.
"""

from __future__ import annotations

from dataclasses import dataclass

from ocu.protocol.extended import VideoFragment
from ocu.records import VideoStats

SEQUENCE_MODULUS = 2**32
HALF_RANGE = SEQUENCE_MODULUS // 2
# A frame this many sequence numbers behind the newest one means the robot restarted its
# counter (about 30 s of video at 30 fps), not that a datagram was held up in the network.
RESTART_GAP = 1000


@dataclass(frozen=True)
class CompleteFrame:
    """A reassembled JPEG with its tags and when its first and last fragments arrived."""

    camera: int
    sequence: int
    capture_time_us: int
    jpeg: bytes
    fragments: int
    first_at: float
    completed_at: float


class _Partial:
    """One frame being reassembled: a buffer of its final size and the indices received."""

    __slots__ = ("buffer", "capture_time_us", "count", "first_at", "received", "seen")

    def __init__(self, fragment: VideoFragment, now: float) -> None:
        self.buffer = bytearray(fragment.frame_bytes)
        self.count = fragment.count
        self.capture_time_us = fragment.capture_time_us
        self.first_at = now
        self.seen = bytearray(fragment.count)
        self.received = 0

    def matches(self, fragment: VideoFragment) -> bool:
        return (
            fragment.frame_bytes == len(self.buffer)
            and fragment.count == self.count
            and fragment.capture_time_us == self.capture_time_us
        )


def sequence_newer(sequence: int, reference: int) -> bool:
    """Whether sequence comes after reference in modulo-2**32 order."""
    return 0 < (sequence - reference) % SEQUENCE_MODULUS < HALF_RANGE


def sequence_behind(sequence: int, reference: int) -> int:
    """How many steps sequence lies behind reference (0 if it is not behind)."""
    gap = (reference - sequence) % SEQUENCE_MODULUS
    return gap if 0 < gap < HALF_RANGE else 0


class Reassembler:
    """Collects fragments into frames; not thread-safe (the link loop alone calls it)."""

    def __init__(self, max_frames: int, max_bytes: int, timeout_s: float) -> None:
        if max_frames < 1 or max_bytes < 1 or not timeout_s > 0.0:
            raise ValueError("reassembly bounds must be positive")
        self.max_frames = max_frames
        self.max_bytes = max_bytes
        self.timeout_s = timeout_s
        self._partials: dict[tuple[int, int], _Partial] = {}
        self._bytes_held = 0
        self._newest: dict[int, int] = {}
        self._newest_at: dict[int, float] = {}
        self._fragments = 0
        self._completed = 0
        self._duplicates = 0
        self._truncated = 0
        self._evicted = 0
        self._expired = 0
        self._out_of_order = 0
        self._inconsistent = 0
        self._restarts = 0

    def stats(self) -> VideoStats:
        """The counters now."""
        return VideoStats(
            fragments=self._fragments,
            completed=self._completed,
            duplicates=self._duplicates,
            truncated=self._truncated,
            evicted=self._evicted,
            expired=self._expired,
            out_of_order=self._out_of_order,
            inconsistent=self._inconsistent,
            restarts=self._restarts,
            frames_held=len(self._partials),
            bytes_held=self._bytes_held,
        )

    def add(self, fragment: VideoFragment, now: float) -> CompleteFrame | None:
        """Take one fragment; the whole frame when this fragment completes it."""
        self._fragments += 1
        self.expire(now)
        camera, sequence = fragment.camera, fragment.sequence
        newest = self._newest.get(camera)
        if newest is not None:
            if sequence == newest:
                self._duplicates += 1  # a late copy of the frame already delivered
                return None
            behind = sequence_behind(sequence, newest)
            silent_s = now - self._newest_at[camera]
            if behind > RESTART_GAP or (behind and silent_s > self.timeout_s):
                self._restart(camera)
            elif behind:
                self._out_of_order += 1
                return None
        if fragment.frame_bytes > self.max_bytes:
            self._inconsistent += 1
            return None
        if fragment.count == 1:
            return self._deliver(fragment, bytes(fragment.payload), fragment.count, now, now)
        key = (camera, sequence)
        partial = self._partials.get(key)
        if partial is None:
            self._make_room(fragment.frame_bytes)
            partial = _Partial(fragment, now)
            self._partials[key] = partial
            self._bytes_held += fragment.frame_bytes
        elif not partial.matches(fragment):
            self._inconsistent += 1
            return None
        if partial.seen[fragment.index]:
            self._duplicates += 1
            return None
        partial.seen[fragment.index] = 1
        partial.received += 1
        end = fragment.offset + len(fragment.payload)
        partial.buffer[fragment.offset : end] = fragment.payload
        if partial.received < partial.count:
            return None
        self._drop(key)
        return self._deliver(fragment, bytes(partial.buffer), partial.count, partial.first_at, now)

    def expire(self, now: float) -> int:
        """Drop partial frames older than the timeout; how many were dropped."""
        limit = now - self.timeout_s
        stale = [key for key, partial in self._partials.items() if partial.first_at < limit]
        for key in stale:
            self._drop(key)
        self._expired += len(stale)
        return len(stale)

    def _deliver(
        self, fragment: VideoFragment, jpeg: bytes, count: int, first_at: float, now: float
    ) -> CompleteFrame:
        camera, sequence = fragment.camera, fragment.sequence
        self._newest[camera] = sequence
        self._newest_at[camera] = now
        # Older partial frames of this camera can no longer be shown: give them up now.
        older = [
            key for key in self._partials if key[0] == camera and sequence_newer(sequence, key[1])
        ]
        for key in older:
            self._drop(key)
        self._truncated += len(older)
        self._completed += 1
        return CompleteFrame(
            camera=camera,
            sequence=sequence,
            capture_time_us=fragment.capture_time_us,
            jpeg=jpeg,
            fragments=count,
            first_at=first_at,
            completed_at=now,
        )

    def reset(self) -> None:
        """Forget every partial frame and newest sequence: a lost robot may come back rebooted."""
        for key in list(self._partials):
            self._drop(key)
        self._newest.clear()
        self._newest_at.clear()

    def _make_room(self, frame_bytes: int) -> None:
        while self._partials and (
            len(self._partials) >= self.max_frames
            or self._bytes_held + frame_bytes > self.max_bytes
        ):
            oldest = next(iter(self._partials))
            self._drop(oldest)
            self._evicted += 1
            self._truncated += 1

    def _restart(self, camera: int) -> None:
        self._restarts += 1
        del self._newest[camera]
        del self._newest_at[camera]
        for key in [key for key in self._partials if key[0] == camera]:
            self._drop(key)

    def _drop(self, key: tuple[int, int]) -> None:
        partial = self._partials.pop(key)
        self._bytes_held -= len(partial.buffer)
