"""Synthetic camera frames: JPEGs that show the camera, a frame counter and moving content.

In a world (ocu.sim.scene) the picture is the world from the camera's mount as the robot
moves; without one, a tinted, scrolling noise pattern with a ball circling.

Each JPEG carries a comment (JPEG COM segment) with the same facts in machine-readable form,
``ocu-sim camera=<name> index=<k> frame=<n> t_mono=<s> quality=<q> torch=<0|1>``, so tests
and tools can check which camera sent a frame and when without reading pixels.
"""

from __future__ import annotations

import colorsys
import io
import math
import time
from collections.abc import Mapping

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from ocu.nav.geometry import Pose
from ocu.profile import CameraMount
from ocu.sim.scene import WorldView

DEFAULT_QUALITY = 75
MIN_QUALITY = 10
MAX_QUALITY = 95
BITRATE_PER_QUALITY_STEP = 20_000.0
# Budget for one video datagram, below the 65,507-byte UDP payload limit with room to spare.
MAX_VIDEO_DATAGRAM_BYTES = 65_000
MAX_JPEG_BYTES = MAX_VIDEO_DATAGRAM_BYTES - 1  # one byte goes to the frame type
QUALITY_STEP_DOWN = 10
DOWNSCALE_FACTOR = 0.75
MIN_FRAME_SIDE_PX = 16
MAX_FRAME_SIDE_PX = 4096
TORCH_GAIN = 1.6
DARK_GAIN = 0.75
NOISE_SIGMA = 40.0
NOISE_BLEND = 0.25
SCROLL_PX_PER_FRAME = 3


def quality_for_bitrate(bitrate: float) -> int:
    """JPEG quality for an RCP video bit-rate: monotonic, clamped, 0 (or invalid) = default."""
    if not math.isfinite(bitrate) or bitrate <= 0.0:
        return DEFAULT_QUALITY
    return int(min(max(bitrate / BITRATE_PER_QUALITY_STEP, MIN_QUALITY), MAX_QUALITY))


def parse_comment(comment: bytes) -> dict[str, str]:
    """The key=value facts of a simulator JPEG comment."""
    fields = comment.decode("ascii", errors="replace").split()
    return dict(item.split("=", 1) for item in fields if "=" in item)


def _gain_table(gain: float) -> list[int]:
    return [min(255, round(value * gain)) for value in range(256)] * 3


class FrameRenderer:
    """Draws and encodes frames for a fixed set of cameras and one frame size."""

    def __init__(
        self,
        camera_names: tuple[str, ...],
        size_px: tuple[int, int],
        *,
        world: WorldView | None = None,
        mounts: tuple[CameraMount | None, ...] = (),
    ) -> None:
        width_px, height_px = size_px
        for side in (width_px, height_px):
            if not MIN_FRAME_SIDE_PX <= side <= MAX_FRAME_SIDE_PX:
                raise ValueError(
                    f"frame size {width_px}x{height_px} outside "
                    f"[{MIN_FRAME_SIDE_PX}, {MAX_FRAME_SIDE_PX}] pixels per side"
                )
        self.camera_names = camera_names
        self.size_px = size_px
        self.world = world
        self.mounts = mounts
        self._backgrounds: dict[int, Image.Image] = {}
        self._font = ImageFont.load_default(size=max(10, height_px // 16))
        self._torch_table = _gain_table(TORCH_GAIN)
        self._dark_table = _gain_table(DARK_GAIN)

    def _background(self, camera: int) -> Image.Image:
        # Built once per camera: a hue of its own so cameras differ at a glance, plus noise so
        # the JPEG size reacts clearly to the quality setting.
        cached = self._backgrounds.get(camera)
        if cached is not None:
            return cached
        hue = camera / max(len(self.camera_names), 1)
        red, green, blue = (round(c * 255) for c in colorsys.hsv_to_rgb(hue, 0.6, 0.9))
        gradient = Image.linear_gradient("L").resize(self.size_px)
        tint = Image.new("RGB", self.size_px, (red, green, blue))
        shaded = Image.composite(tint, Image.new("RGB", self.size_px), gradient)
        noise = Image.effect_noise(self.size_px, NOISE_SIGMA).convert("RGB")
        background = Image.blend(shaded, noise, NOISE_BLEND)
        self._backgrounds[camera] = background
        return background

    def render(
        self,
        camera: int,
        frame_number: int,
        quality: int,
        *,
        torch: bool = False,
        time_s: float | None = None,
        pose: Pose | None = None,
        joints_rad: Mapping[str, float] | None = None,
    ) -> bytes:
        """One JPEG of a camera that fits a single datagram (quality or size lowered if needed);
        `joints_rad` places the cameras mounted on the arm."""
        mono_s = time.monotonic() if time_s is None else time_s
        name = self.camera_names[camera]
        image = self._draw(camera, name, frame_number, torch, pose, joints_rad=joints_rad)
        quality = min(max(quality, 1), 100)
        while True:
            comment = (
                f"ocu-sim camera={name} index={camera} frame={frame_number} "
                f"t_mono={mono_s:.6f} quality={quality} torch={int(torch)}"
            ).encode("ascii")
            buffer = io.BytesIO()
            image.save(buffer, "JPEG", quality=quality, comment=comment)
            jpeg = buffer.getvalue()
            if len(jpeg) <= MAX_JPEG_BYTES:
                return jpeg
            if quality > MIN_QUALITY:
                quality = max(MIN_QUALITY, quality - QUALITY_STEP_DOWN)
            else:
                width_px, height_px = image.size
                image = image.resize(
                    (
                        max(1, int(width_px * DOWNSCALE_FACTOR)),
                        max(1, int(height_px * DOWNSCALE_FACTOR)),
                    )
                )

    def _world(
        self, camera: int, pose: Pose, joints_rad: Mapping[str, float] | None
    ) -> Image.Image:
        assert self.world is not None
        width_px = self.size_px[0]
        mount = self.mounts[camera] if camera < len(self.mounts) else None
        # A 90-degree wide, undistorted view (the vendor stream's lens is not modelled).
        bgr = self.world.render(
            pose, mount, self.size_px, (width_px / 2.0, width_px / 2.0), joints_rad=joints_rad
        )
        return Image.fromarray(np.ascontiguousarray(bgr[..., ::-1]), "RGB")

    def _draw(
        self,
        camera: int,
        name: str,
        frame_number: int,
        torch: bool,
        pose: Pose | None = None,
        *,
        joints_rad: Mapping[str, float] | None = None,
    ) -> Image.Image:
        width_px, height_px = self.size_px
        if self.world is not None and pose is not None:
            # The world is drawn fully lit; without the headlight it is darker.
            image = self._world(camera, pose, joints_rad)
            if not torch:
                image = image.point(self._dark_table)
            self._text(image, camera, name, frame_number, torch)
            return image
        background = self._background(camera)
        # Scroll the background so consecutive frames differ (moving content).
        shift_px = (frame_number * SCROLL_PX_PER_FRAME) % width_px
        image = Image.new("RGB", self.size_px)
        image.paste(background.crop((shift_px, 0, width_px, height_px)), (0, 0))
        if shift_px:
            image.paste(background.crop((0, 0, shift_px, height_px)), (width_px - shift_px, 0))
        image = image.point(self._torch_table if torch else self._dark_table)

        draw = ImageDraw.Draw(image)
        # A ball circling the centre: the second moving thing, easy to follow by eye.
        angle_rad = frame_number * 0.15
        radius_px = min(width_px, height_px) // 10
        centre_x = width_px / 2 + math.cos(angle_rad) * width_px / 4
        centre_y = height_px / 2 + math.sin(angle_rad) * height_px / 4
        draw.ellipse(
            (
                centre_x - radius_px,
                centre_y - radius_px,
                centre_x + radius_px,
                centre_y + radius_px,
            ),
            fill=(255, 255, 255),
            outline=(0, 0, 0),
        )
        self._text(image, camera, name, frame_number, torch)
        return image

    def _text(
        self, image: Image.Image, camera: int, name: str, frame_number: int, torch: bool
    ) -> None:
        height_px = self.size_px[1]
        draw = ImageDraw.Draw(image)
        wall_clock = time.strftime("%H:%M:%S") + f".{int(time.time() * 1000) % 1000:03d}"
        lines = (
            f"{name} (camera {camera + 1})",
            f"frame {frame_number}",
            f"sent {wall_clock}",
            "torch ON" if torch else "torch off",
        )
        line_height_px = max(12, height_px // 12)
        for index, text in enumerate(lines):
            position = (4, 2 + index * line_height_px)
            draw.text(
                position,
                text,
                fill=(255, 255, 0),
                font=self._font,
                stroke_width=1,
                stroke_fill=(0, 0, 0),
            )
