"""StallWatch: a silence of the GUI thread counts only if it began with motion commanded."""

from __future__ import annotations

import pytest

from ocu.console.stall import StallWatch


def test_a_gap_that_began_with_motion_is_a_stall() -> None:
    watch = StallWatch(0.4)
    watch.alive(0.0, moving=True)
    watch.alive(0.05, moving=True)
    watch.alive(0.60, moving=True)  # 0.55 s silent while driving
    assert watch.take_stall() == pytest.approx(0.55)
    assert watch.take_stall() is None  # taken once


def test_a_key_pressed_after_a_still_gap_is_not_a_stall() -> None:
    watch = StallWatch(0.4)
    watch.alive(0.0, moving=False)
    watch.alive(0.90, moving=True)  # the key, pressed after 0.9 s of silence
    watch.alive(0.91, moving=True)  # the tick just after it
    assert watch.take_stall() is None


def test_short_gaps_and_stopping_before_the_gap_are_not_stalls() -> None:
    watch = StallWatch(0.4)
    watch.alive(0.0, moving=True)
    watch.alive(0.39, moving=False)  # stopped within the limit
    watch.alive(2.0, moving=False)
    assert watch.take_stall() is None
    with pytest.raises(ValueError, match="positive"):
        StallWatch(0.0)
