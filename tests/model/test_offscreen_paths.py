"""Both offscreen paths, each forced in a process of its own (PyOpenGL fixes its platform at
import): OSMesa where its library is installed, EGL's surfaceless platform where libEGL is.
The same pose drawn both ways gives the same picture."""

from __future__ import annotations

import ctypes.util
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest
from PIL import Image

from ocu.render.platform import OffscreenMode, osmesa_installed

PATH_NAMES = {"osmesa": "OSMesa", "egl": "EGL"}


def _available(mode: OffscreenMode) -> bool:
    if mode == "osmesa":
        return osmesa_installed()
    return ctypes.util.find_library("EGL") is not None


def _shoot(mode: OffscreenMode, out: Path) -> str:
    env = {**os.environ, "PYOPENGL_PLATFORM": mode}
    command = [sys.executable, "-m", "ocu", "screenshot", str(out), "--size", "400x300"]
    command += ["--joints", "shoulder=40", "elbow=-60", "--ghost", "waist=30"]
    result = subprocess.run(
        command,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    return result.stdout


def _image(path: Path) -> npt.NDArray[np.int16]:
    return np.asarray(Image.open(path).convert("RGB")).astype(np.int16)


@pytest.mark.parametrize("mode", ["osmesa", "egl"])
def test_each_offscreen_path_draws_and_says_which(mode: OffscreenMode, tmp_path: Path) -> None:
    if not _available(mode):
        pytest.skip(f"{PATH_NAMES[mode]} is not installed on this machine")
    out = tmp_path / f"{mode}.png"
    stdout = _shoot(mode, out)
    assert f"drawn through {PATH_NAMES[mode]} (" in stdout
    image = _image(out)
    background = image[0, 0]
    drawn = (np.abs(image - background).max(axis=2) > 24).mean()
    assert drawn > 0.05, f"{mode}: only {drawn:.1%} of the picture differs from the background"


def test_osmesa_and_egl_draw_the_same_picture(tmp_path: Path) -> None:
    if not (_available("osmesa") and _available("egl")):
        pytest.skip("needs both OSMesa and EGL")
    _shoot("osmesa", tmp_path / "osmesa.png")
    _shoot("egl", tmp_path / "egl.png")
    a, b = _image(tmp_path / "osmesa.png"), _image(tmp_path / "egl.png")
    assert a.shape == b.shape
    differs = np.abs(a - b).max(axis=2) > 32
    # The same rasteriser (llvmpipe) behind both: at most a few edge pixels may differ.
    assert differs.mean() < 0.005, f"{differs.mean():.2%} of the pixels differ"
