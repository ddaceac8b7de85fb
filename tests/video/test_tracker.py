"""The click-to-track tracker on synthetic scenes: follow, lose, find again, never jump."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from ocu.video.tracker import Box, Tracker, TrackerError, TrackState

WIDTH, HEIGHT = 640, 480
OBJECT_PX = 60


def background(seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    noise = rng.integers(60, 200, (HEIGHT, WIDTH, 3), dtype=np.uint8)
    return cv2.GaussianBlur(noise, (0, 0), 4)


def textured_object(seed: int = 2, hue_bgr: tuple[int, int, int] = (40, 40, 220)) -> np.ndarray:
    rng = np.random.default_rng(seed)
    patch = np.zeros((OBJECT_PX, OBJECT_PX, 3), np.uint8)
    patch[:] = hue_bgr
    for _ in range(12):  # a pattern the template can lock onto
        x, y = rng.integers(0, OBJECT_PX - 10, 2)
        cv2.rectangle(patch, (int(x), int(y)), (int(x) + 8, int(y) + 8), (255, 255, 255), -1)
    return patch


def scene(
    at: tuple[int, int] | None,
    base: np.ndarray,
    thing: np.ndarray,
    extra: list[tuple[np.ndarray, tuple[int, int]]] | None = None,
) -> np.ndarray:
    image = base.copy()
    for patch, (x, y) in extra or []:
        image[y : y + OBJECT_PX, x : x + OBJECT_PX] = patch
    if at is not None:
        x, y = at
        image[y : y + OBJECT_PX, x : x + OBJECT_PX] = thing
    return image


def box_at(x: int, y: int) -> Box:
    return Box(x / WIDTH, y / HEIGHT, OBJECT_PX / WIDTH, OBJECT_PX / HEIGHT)


def centre_error_px(box: Box | None, x: int, y: int) -> float:
    assert box is not None
    cx, cy = box.centre
    return float(np.hypot(cx * WIDTH - (x + OBJECT_PX / 2), cy * HEIGHT - (y + OBJECT_PX / 2)))


def test_follows_a_moving_object_whatever_size_the_frames_come_at() -> None:
    base, thing = background(), textured_object()
    tracker = Tracker()
    tracker.start(scene((100, 200), base, thing), box_at(100, 200))
    worst = 0.0
    for step in range(1, 60):
        x, y = 100 + 6 * step, 200 + round(40 * np.sin(step / 8))
        frame = scene((x, y), base, thing)
        if step % 3 == 0:  # the view resized: a frame at another size
            frame = cv2.resize(frame, (WIDTH // 2, HEIGHT // 2), interpolation=cv2.INTER_AREA)
        result = tracker.update(frame)
        assert result.state is TrackState.TRACKING, step
        worst = max(worst, centre_error_px(result.box, x, y))
    assert worst < 6.0  # pixels of the 640x480 frame


def test_lost_when_hidden_and_found_again_elsewhere_not_on_a_lookalike() -> None:
    base, thing = background(), textured_object()
    # Same colour, other pattern: the colour model likes it, the template must not.
    lookalike = textured_object(seed=9)
    distractor = [(lookalike, (480, 60))]
    tracker = Tracker()
    tracker.start(scene((100, 300), base, thing, distractor), box_at(100, 300))
    for _ in range(5):  # out of view
        result = tracker.update(scene(None, base, thing, distractor))
        assert result.state is TrackState.LOST
        assert result.box is None
    assert tracker.lost_frames == 5
    result = tracker.update(scene((300, 150), base, thing, distractor))
    assert result.state is TrackState.TRACKING
    assert result.refound
    assert centre_error_px(result.box, 300, 150) < 6.0


def test_a_box_too_small_is_refused_and_stop_forgets() -> None:
    tracker = Tracker()
    with pytest.raises(TrackerError, match="too small"):
        tracker.start(background(), Box(0.5, 0.5, 0.005, 0.005))
    with pytest.raises(TrackerError, match="plain surface"):
        tracker.start(background(), box_at(10, 10))  # nothing there to correlate
    tracker.start(scene((10, 10), background(), textured_object()), box_at(10, 10))
    tracker.stop()
    assert tracker.update(background()).state is TrackState.IDLE


def test_a_click_inside_a_plain_object_takes_its_outline() -> None:
    base = background()
    side = 120
    plain = np.zeros((side, side, 3), np.uint8)
    plain[:] = (30, 30, 200)

    def with_plain(x: int, y: int) -> np.ndarray:
        image = base.copy()
        image[y : y + side, x : x + side] = plain
        return image

    tracker = Tracker()
    click = Box(
        (200 + side / 2 - 15) / WIDTH, (150 + side / 2 - 15) / HEIGHT, 30 / WIDTH, 30 / HEIGHT
    )
    tracker.start(with_plain(200, 150), click)
    assert tracker.box is not None
    assert tracker.box.width * WIDTH > side  # the outline is inside the template
    for step in range(1, 8):
        x, y = 200 + 6 * step, 150 + 3 * step
        result = tracker.update(with_plain(x, y))
        assert result.state is TrackState.TRACKING
        assert result.box is not None
        cx, cy = result.box.centre
        assert np.hypot(cx * WIDTH - (x + side / 2), cy * HEIGHT - (y + side / 2)) < 4.0
