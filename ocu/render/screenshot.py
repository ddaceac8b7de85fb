"""`ocu screenshot OUT.png`: render the robot model to a PNG with no display (OSMesa or EGL)."""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np
import numpy.typing as npt

from ocu.model.packages import add_package_path_option
from ocu.model.urdf import RobotModel, UrdfError, load_urdf, profile_urdf_path
from ocu.profile import ProfileError, load_profile
from ocu.render.camera import VIEWS, OrbitCamera
from ocu.render.platform import configure_gl_platform
from ocu.render.scene import build_frame, model_bounds


class ScreenshotError(RuntimeError):
    """The screenshot could not be made; the message says why."""


def parse_angles(items: Sequence[str], model: RobotModel, option: str) -> dict[str, float]:
    """`name=value` pairs to joint values: degrees for a revolute joint (to radians), metres
    for a prismatic one, checked against the model's joints."""
    joints = model.tree.actuated_joints
    angles: dict[str, float] = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep:
            raise ScreenshotError(f"{option} {item!r}: expected name=degrees (metres if prismatic)")
        if name not in joints:
            raise ScreenshotError(
                f"{option} {item!r}: unknown joint {name!r}; joints: {', '.join(joints)}"
            )
        try:
            number = float(value)
        except ValueError:
            raise ScreenshotError(f"{option} {item!r}: {value!r} is not a number") from None
        if not math.isfinite(number):
            raise ScreenshotError(f"{option} {item!r}: the value must be finite")
        prismatic = model.tree.joint(name).type == "prismatic"
        angles[name] = number if prismatic else math.radians(number)
    return angles


def describe_value(model: RobotModel, name: str, value: float) -> str:
    """A joint value in its unit: '35 deg' or '0.35 m'."""
    if model.tree.joint(name).type == "prismatic":
        return f"{value:g} m"
    return f"{math.degrees(value):g} deg"


def parse_size(text: str) -> tuple[int, int]:
    """`WxH` to a pixel size."""
    width, sep, height = text.lower().partition("x")
    try:
        size = (int(width), int(height))
    except ValueError:
        raise ScreenshotError(f"--size {text!r}: expected WIDTHxHEIGHT, e.g. 800x600") from None
    if not sep or not (16 <= size[0] <= 8192 and 16 <= size[1] <= 8192):
        raise ScreenshotError(f"--size {text!r}: expected WIDTHxHEIGHT between 16 and 8192")
    return size


def render_model(
    model: RobotModel,
    size: tuple[int, int] = (800, 600),
    view: str = "iso",
    *,
    joints: Mapping[str, float] | None = None,
    ghost: Mapping[str, float] | None = None,
    stale: Sequence[str] = (),
    samples: int = 4,
    report: Callable[[str], None] | None = None,
) -> npt.NDArray[np.uint8]:
    """An RGBA image (rows top first) of the model in a pose, framed from a preset view.

    `report` is told which offscreen path drew (e.g. 'EGL (llvmpipe ...)')."""
    configure_gl_platform("offscreen")
    from ocu.render.offscreen import OffscreenRenderer  # after the platform choice
    from ocu.render.renderer import ModelRenderer

    live = model.tree.copy()
    live.set_positions(joints or {})
    ghost_tree = None
    if ghost:
        ghost_tree = live.copy()
        ghost_tree.set_positions(ghost)
    if model.triangle_count == 0:
        raise ScreenshotError(
            f"{model.source}: nothing to draw: the model holds no triangles (see the notes)"
        )
    low, high = model_bounds(model, live)
    if ghost_tree is not None:
        ghost_low, ghost_high = model_bounds(model, ghost_tree)
        low, high = np.minimum(low, ghost_low), np.maximum(high, ghost_high)
    if not (np.isfinite(low).all() and np.isfinite(high).all()):
        raise ScreenshotError(f"{model.source}: nothing to draw: the model's extent is not finite")
    camera = OrbitCamera.framing(low, high, view)
    width, height = size
    offscreen = OffscreenRenderer(ModelRenderer(model), width, height, samples=samples)
    try:
        if report is not None:
            report(offscreen.describe())
        frame = build_frame(
            model, camera, width / height, live=live, ghost=ghost_tree, stale_joints=stale
        )
        return offscreen.render(frame)
    finally:
        offscreen.close()


def build_parser() -> argparse.ArgumentParser:
    """The command line of `ocu screenshot`."""
    parser = argparse.ArgumentParser(
        prog="ocu screenshot",
        description=(
            "Render the robot model to a PNG without a display (OSMesa where installed, "
            "else EGL; PYOPENGL_PLATFORM=osmesa|egl chooses)."
        ),
    )
    parser.add_argument("out", type=Path, help="PNG file to write")
    parser.add_argument(
        "--joints",
        nargs="+",
        default=[],
        metavar="NAME=VALUE",
        help="joint values: degrees, or metres for a prismatic joint",
    )
    parser.add_argument(
        "--ghost", nargs="+", default=[], metavar="NAME=DEG", help="targets shown as a ghost"
    )
    parser.add_argument(
        "--stale", nargs="+", default=[], metavar="NAME", help="joints drawn as stale"
    )
    parser.add_argument("--size", default="800x600", help="image size WxH (default 800x600)")
    parser.add_argument("--view", choices=tuple(VIEWS), default="iso", help="camera preset")
    parser.add_argument(
        "--urdf", type=Path, default=None, help="URDF to draw (default: the profile's robot)"
    )
    parser.add_argument("--profile", type=Path, default=None, help="robot profile TOML")
    add_package_path_option(parser)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point; argv are the arguments after `screenshot`. Returns the exit status."""
    args = build_parser().parse_args(argv)
    try:
        profile = load_profile(args.profile)  # a bad profile is reported here, as elsewhere
        urdf = args.urdf if args.urdf is not None else profile_urdf_path(profile)
        model = load_urdf(urdf, package_paths=args.package_path)
        joints = parse_angles(args.joints, model, "--joints")
        ghost = parse_angles(args.ghost, model, "--ghost")
        for name in args.stale:
            if name not in model.tree.joints:
                raise ScreenshotError(f"--stale {name!r}: unknown joint")
        for warning in model.warnings:
            print(f"note: {warning}", file=sys.stderr)
        for name, angle in joints.items():
            limits = model.tree.joint(name).limits
            if limits is not None and not limits[0] - 1e-9 <= angle <= limits[1] + 1e-9:
                low, high = (describe_value(model, name, v) for v in limits)
                print(
                    f"note: {name}={describe_value(model, name, angle)} is outside its limits "
                    f"[{low}, {high}]",
                    file=sys.stderr,
                )
        size = parse_size(args.size)
        paths: list[str] = []
        rgba = render_model(
            model,
            size,
            args.view,
            joints=joints,
            ghost=ghost,
            stale=args.stale,
            report=paths.append,
        )
        save_png(rgba, args.out)
    except (ScreenshotError, UrdfError, ProfileError, OSError, RuntimeError) as err:
        print(f"ocu screenshot: {err}", file=sys.stderr)
        return 1
    print(f"wrote {args.out} ({size[0]}x{size[1]}) drawn through {', '.join(paths)}")
    return 0


def save_png(rgba: npt.NDArray[np.uint8], path: Path) -> None:
    """Write an RGBA array as PNG."""
    from PIL import Image  # only screenshots need Pillow

    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(rgba, "RGBA").convert("RGB").save(path)
