"""The clicked object's colour blob: where it is and how large it looks (seed 003 §2.2), no Qt.

Seed 003 finds its object by colour with OpenCV and takes the blob's area as a proxy for its
distance. The template tracker (ocu.video.tracker) follows a box of a fixed size; this gives
the size: the hue of the clicked object is learnt from the pixels around the click, and each
frame the blob of that hue nearest to where the object was is measured (its centroid and the
diameter of a disc of its area).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import cast

import cv2
import numpy as np
import numpy.typing as npt

Image = npt.NDArray[np.uint8]
# Pixels this close in hue (OpenCV's 0-180) to the learnt one, and this saturated and bright,
# belong to the object.
HUE_TOLERANCE = 12
MIN_SATURATION = 70
MIN_VALUE = 40
# The click's neighbourhood the hue is learnt from (fraction of the width), and the blob's
# least size (pixels) to count.
LEARN_FRACTION = 0.03
MIN_AREA_PX = 6
# Pictures wider than this are measured on a copy this wide.
WORKING_WIDTH_PX = 320


class BlobError(ValueError):
    """The clicked spot has no colour to follow (grey, dark)."""


@dataclass(frozen=True)
class Blob:
    """The object in one picture: centre (normalised) and diameter (fraction of the width)."""

    centre: tuple[float, float]
    size: float
    # Cut by the picture's edge: its size (and centre) are not the object's.
    at_edge: bool = False


def _hsv(image: Image) -> Image:
    bgr = image[:, :, :3] if image.shape[2] == 4 else image
    return cast(Image, cv2.cvtColor(np.ascontiguousarray(bgr), cv2.COLOR_BGR2HSV))


class ColourBlob:
    """The hue learnt at the click; `measure` finds the blob in a picture."""

    def __init__(self, image: Image, point: tuple[float, float]) -> None:
        height, width = image.shape[:2]
        radius = max(2, round(LEARN_FRACTION * width))
        x, y = round(point[0] * (width - 1)), round(point[1] * (height - 1))
        patch = _hsv(
            image[max(0, y - radius) : y + radius + 1, max(0, x - radius) : x + radius + 1]
        )
        pixels = patch.reshape(-1, 3)
        coloured = pixels[(pixels[:, 1] >= MIN_SATURATION) & (pixels[:, 2] >= MIN_VALUE)]
        if len(coloured) < max(4, len(pixels) // 4):
            raise BlobError("no colour to follow there (grey or dark): click a coloured object")
        # The circular mean of the hues (red wraps around 0/180).
        angles = coloured[:, 0].astype(np.float64) * (math.tau / 180.0)
        mean = math.atan2(float(np.mean(np.sin(angles))), float(np.mean(np.cos(angles))))
        self.hue = (mean % math.tau) * 180.0 / math.tau
        self.last: Blob | None = None
        found = self.measure(image, point)
        if found is None:
            raise BlobError("no blob of that colour at the click")

    def measure(self, image: Image, near: tuple[float, float] | None = None) -> Blob | None:
        """The blob of the learnt hue nearest `near` (normalised; else where it was last)."""
        full_width = image.shape[1]
        if full_width > WORKING_WIDTH_PX:  # measured on a copy at most this wide (speed)
            scale = WORKING_WIDTH_PX / full_width
            size = (WORKING_WIDTH_PX, max(1, round(image.shape[0] * scale)))
            image = cast(Image, cv2.resize(image, size, interpolation=cv2.INTER_AREA))
        height, width = image.shape[:2]
        hsv = _hsv(image)
        hue = round(self.hue) % 180
        low, high = hue - HUE_TOLERANCE, hue + HUE_TOLERANCE
        ranges = [(max(low, 0), min(high, 179))]
        if low < 0:
            ranges.append((180 + low, 179))
        if high > 179:
            ranges.append((0, high - 180))
        mask = np.zeros((height, width), np.uint8)
        for start, end in ranges:
            inside = cv2.inRange(
                hsv, np.array([start, MIN_SATURATION, MIN_VALUE]), np.array([end, 255, 255])
            )
            mask = cast(Image, cv2.bitwise_or(mask, inside))
        count, _labels, stats, centroids = cv2.connectedComponentsWithStats(mask, connectivity=8)
        anchor = near if near is not None else (self.last.centre if self.last else (0.5, 0.5))
        best: tuple[float, Blob] | None = None
        for label in range(1, count):
            area = int(stats[label, cv2.CC_STAT_AREA])
            if area < MIN_AREA_PX:
                continue
            # Pixel centres are at half-integers of the normalised picture.
            cx = (float(centroids[label][0]) + 0.5) / width
            cy = (float(centroids[label][1]) + 0.5) / height
            left, top = int(stats[label, cv2.CC_STAT_LEFT]), int(stats[label, cv2.CC_STAT_TOP])
            right = left + int(stats[label, cv2.CC_STAT_WIDTH])
            bottom = top + int(stats[label, cv2.CC_STAT_HEIGHT])
            edge = left == 0 or top == 0 or right == width or bottom == height
            blob = Blob((cx, cy), 2.0 * math.sqrt(area / math.pi) / width, edge)
            gap = math.hypot(cx - anchor[0], (cy - anchor[1]) * height / width)
            if best is None or gap < best[0]:
                best = (gap, blob)
        if best is None:
            return None
        self.last = best[1]
        return best[1]
