"""Follow an object the operator clicked in a camera view (seed 003 §2.2), no Qt.

The tracker works on a copy of each frame scaled to a fixed working width, so the view's
cell size (frames are decoded at the size they are shown) does not change what it sees; boxes
are given and returned in normalised coordinates (0..1 of the frame's width and height).

A click inside a plain surface (a painted box: no texture for the correlation) grows the box to
the surface's outline by a flood fill from the click, padded so its edges are in the template.

Two models of the object, both from the clicked box:
- a template, found again in each frame by normalised cross-correlation in a window around
  where it was (`cv2.matchTemplate`), and blended slowly towards what it finds, so lighting and
  a slowly turning object are followed without drifting onto the background;
- a hue-saturation histogram, the second opinion when the object was lost (occluded, out of
  view, blurred): the template is then searched over the whole frame, and the best match is
  taken up again only if it is good and its colours are the object's (no jumping onto
  something of the same shape or the same colour alone).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum
from typing import Any, cast

import cv2
import numpy as np
import numpy.typing as npt

Image = npt.NDArray[np.uint8]

WORKING_WIDTH_PX = 320
# Normalised cross-correlation above which the template is found where it matched best.
MATCH_THRESHOLD = 0.55
# ...and above which a candidate found by colour is taken as the object again.
REFIND_THRESHOLD = 0.6
# The search window around the last box: this many box sizes each way.
SEARCH_MARGIN_BOXES = 1.5
# Weight of the newest appearance in the template when the match is good.
TEMPLATE_ADAPT = 0.1
ADAPT_ABOVE = 0.8
MIN_BOX_PX = 8
HIST_BINS = (30, 32)
# Mean colour-model response (0..1) a re-found box must have.
MIN_COLOUR_SUPPORT = 0.15
# A template flatter than this (grey-level standard deviation) cannot be matched by correlation:
# the click fell inside a plain surface, and the box grows to the surface's outline instead.
MIN_TEMPLATE_STD = 6.0
# Flood fill of the plain surface: neighbours within this much of the clicked colour (BGR).
FILL_TOLERANCE = 14
# The grown box: the outline plus this fraction of its size on each side (its edges are what
# the correlation sees), at most this fraction of the frame each way.
FILL_PAD = 0.2
MAX_BOX_FRACTION = 0.6
# Pixels too dark or too grey carry no hue: left out of the colour model.
MIN_SATURATION = 40
MIN_VALUE = 30


class TrackerError(ValueError):
    """A box the tracker cannot start from."""


@dataclass(frozen=True)
class Box:
    """A box in normalised frame coordinates: left, top, width, height in 0..1."""

    x: float
    y: float
    width: float
    height: float

    @property
    def centre(self) -> tuple[float, float]:
        """The box's centre (normalised)."""
        return self.x + self.width / 2.0, self.y + self.height / 2.0

    def to_pixels(self, width_px: int, height_px: int) -> tuple[int, int, int, int]:
        """x, y, width, height in pixels of a frame of that size."""
        return (
            round(self.x * width_px),
            round(self.y * height_px),
            max(1, round(self.width * width_px)),
            max(1, round(self.height * height_px)),
        )

    @classmethod
    def around(cls, centre: tuple[float, float], size: float, aspect: float) -> Box:
        """A box of `size` (fraction of the frame width) centred on a point."""
        width = size
        height = size * aspect
        return cls(centre[0] - width / 2.0, centre[1] - height / 2.0, width, height)


class TrackState(Enum):
    """What the tracker knows of the object."""

    IDLE = "idle"
    TRACKING = "tracking"
    LOST = "lost"


@dataclass(frozen=True)
class TrackResult:
    """One frame's outcome: where the object is (None when lost) and how sure."""

    state: TrackState
    box: Box | None
    score: float
    # True on the frame the object was found again after being lost.
    refound: bool = False


class Tracker:
    """Template and colour tracking of one object in one camera's frames."""

    def __init__(self, working_width_px: int = WORKING_WIDTH_PX) -> None:
        self.working_width_px = working_width_px
        self.state = TrackState.IDLE
        self.box: Box | None = None
        self.lost_frames = 0
        self._template: npt.NDArray[np.float32] | None = None
        self._hist: npt.NDArray[Any] | None = None
        self._box_px: tuple[int, int, int, int] | None = None

    def start(self, image: Image, box: Box) -> None:
        """Follow what is inside `box` of this frame (BGR or BGRA)."""
        work = self._working(image)
        height, width = work.shape[:2]
        x, y, w, h = _clip_box(box.to_pixels(width, height), width, height)
        if w < MIN_BOX_PX or h < MIN_BOX_PX:
            raise TrackerError(
                f"box too small to track: {w}x{h} px at {width} px wide (at least {MIN_BOX_PX})"
            )
        patch = work[y : y + h, x : x + w]
        if _flat(patch):
            x, y, w, h = _outline(work, (x + w // 2, y + h // 2))
            patch = work[y : y + h, x : x + w]
            if _flat(patch):
                raise TrackerError("nothing to follow there: a plain surface with no outline")
        self._template = cv2.cvtColor(patch, cv2.COLOR_BGR2GRAY).astype(np.float32)
        self._hist = _colour_model(patch)
        self._box_px = (x, y, w, h)
        self.box = _normalised((x, y, w, h), width, height)
        self.state = TrackState.TRACKING
        self.lost_frames = 0

    def stop(self) -> None:
        """Forget the object."""
        self.state = TrackState.IDLE
        self.box = None
        self._template = None
        self._hist = None
        self._box_px = None

    def update(self, image: Image) -> TrackResult:
        """Find the object in the next frame."""
        if self.state is TrackState.IDLE or self._template is None or self._box_px is None:
            return TrackResult(TrackState.IDLE, None, 0.0)
        work = self._working(image)
        gray = cv2.cvtColor(work, cv2.COLOR_BGR2GRAY).astype(np.float32)
        height, width = gray.shape
        if self.state is TrackState.TRACKING:
            found = self._match_near(gray, self._box_px)
            if found is not None and found[1] >= MATCH_THRESHOLD:
                box_px, score = found
                self._follow(gray, box_px, score)
                self.box = _normalised(box_px, width, height)
                return TrackResult(TrackState.TRACKING, self.box, score)
            self.state = TrackState.LOST
            self.lost_frames = 0
        self.lost_frames += 1
        candidate = self._refind(work, gray)
        if candidate is not None:
            box_px, score = candidate
            self._follow(gray, box_px, score)
            self.state = TrackState.TRACKING
            self.box = _normalised(box_px, width, height)
            return TrackResult(TrackState.TRACKING, self.box, score, refound=True)
        return TrackResult(TrackState.LOST, None, 0.0)

    # ---- internals -------------------------------------------------------------------------

    def _working(self, image: Image) -> Image:
        if image.ndim == 3 and image.shape[2] == 4:
            image = cast(Image, cv2.cvtColor(image, cv2.COLOR_BGRA2BGR))
        height, width = image.shape[:2]
        if width == self.working_width_px:
            return image
        scale = self.working_width_px / width
        size = (self.working_width_px, max(1, round(height * scale)))
        return cast(Image, cv2.resize(image, size, interpolation=cv2.INTER_AREA))

    def _match_near(
        self, gray: npt.NDArray[np.float32], box_px: tuple[int, int, int, int]
    ) -> tuple[tuple[int, int, int, int], float] | None:
        assert self._template is None or self._template.ndim == 2
        template = self._template
        assert template is not None
        height, width = gray.shape
        x, y, w, h = box_px
        margin_x = math.ceil(w * SEARCH_MARGIN_BOXES)
        margin_y = math.ceil(h * SEARCH_MARGIN_BOXES)
        left, top = max(0, x - margin_x), max(0, y - margin_y)
        right, bottom = min(width, x + w + margin_x), min(height, y + h + margin_y)
        return _best_match(gray[top:bottom, left:right], template, (left, top))

    def _refind(
        self, work: Image, gray: npt.NDArray[np.float32]
    ) -> tuple[tuple[int, int, int, int], float] | None:
        """The best template match over the whole frame, if its colours are the object's."""
        assert self._hist is not None
        assert self._template is not None
        found = _best_match(gray, self._template, (0, 0))
        if found is None or found[1] < REFIND_THRESHOLD:
            return None
        x, y, w, h = found[0]
        hsv = cv2.cvtColor(work[y : y + h, x : x + w], cv2.COLOR_BGR2HSV)
        projection = cv2.calcBackProject([hsv], [0, 1], self._hist, [0, 180, 0, 256], 1)
        if float(projection.mean()) / 255.0 < MIN_COLOUR_SUPPORT:
            return None  # the right shape in the wrong colours: not the object
        return found

    def _follow(
        self, gray: npt.NDArray[np.float32], box_px: tuple[int, int, int, int], score: float
    ) -> None:
        self._box_px = box_px
        if score >= ADAPT_ABOVE and self._template is not None:
            x, y, w, h = box_px
            patch = gray[y : y + h, x : x + w]
            if patch.shape == self._template.shape:
                cv2.accumulateWeighted(patch, self._template, TEMPLATE_ADAPT)


def _best_match(
    region: npt.NDArray[np.float32],
    template: npt.NDArray[np.float32],
    origin: tuple[int, int],
) -> tuple[tuple[int, int, int, int], float] | None:
    h, w = template.shape
    if region.shape[0] < h or region.shape[1] < w:
        return None
    scores = cv2.matchTemplate(region, template, cv2.TM_CCOEFF_NORMED)
    _, best, _, at = cv2.minMaxLoc(scores)
    if not math.isfinite(best):
        return None
    return (origin[0] + at[0], origin[1] + at[1], w, h), float(best)


def _flat(patch: Image) -> bool:
    gray = cv2.cvtColor(patch, cv2.COLOR_BGR2GRAY)
    return float(gray.std()) < MIN_TEMPLATE_STD


def _outline(work: Image, seed: tuple[int, int]) -> tuple[int, int, int, int]:
    """The box around the plain surface at `seed`, padded so that its edges are inside."""
    height, width = work.shape[:2]
    mask = np.zeros((height + 2, width + 2), np.uint8)
    tolerance = (FILL_TOLERANCE,) * 3
    flags = 4 | cv2.FLOODFILL_FIXED_RANGE | cv2.FLOODFILL_MASK_ONLY | (255 << 8)
    cv2.floodFill(work.copy(), mask, seed, (0, 0, 0), tolerance, tolerance, flags)
    x, y, w, h = cv2.boundingRect(mask[1:-1, 1:-1])
    centre_x, centre_y = x + w / 2.0, y + h / 2.0
    w = min(round(w * (1 + 2 * FILL_PAD)) + 4, round(width * MAX_BOX_FRACTION))
    h = min(round(h * (1 + 2 * FILL_PAD)) + 4, round(height * MAX_BOX_FRACTION))
    # At the frame's edge the box shrinks about the surface's middle rather than shifting:
    # the template's middle is what the controller centres.
    w = max(MIN_BOX_PX, min(w, 2 * math.floor(min(centre_x, width - centre_x))))
    h = max(MIN_BOX_PX, min(h, 2 * math.floor(min(centre_y, height - centre_y))))
    return _clip_box((round(centre_x - w / 2.0), round(centre_y - h / 2.0), w, h), width, height)


def _colour_model(patch: Image) -> npt.NDArray[Any]:
    hsv = cv2.cvtColor(patch, cv2.COLOR_BGR2HSV)
    mask = cv2.inRange(hsv, (0, MIN_SATURATION, MIN_VALUE), (180, 255, 255))
    hist = cv2.calcHist([hsv], [0, 1], mask, list(HIST_BINS), [0, 180, 0, 256])
    cv2.normalize(hist, hist, 0, 255, cv2.NORM_MINMAX)
    return cast(npt.NDArray[Any], hist)


def _clip_box(box: tuple[int, int, int, int], width: int, height: int) -> tuple[int, int, int, int]:
    x, y, w, h = box
    w, h = min(w, width), min(h, height)
    return min(max(0, x), width - w), min(max(0, y), height - h), w, h


def _normalised(box: tuple[int, int, int, int], width: int, height: int) -> Box:
    x, y, w, h = box
    return Box(x / width, y / height, w / width, h / height)
