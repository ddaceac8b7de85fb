"""The operator's stored poses: a TOML file beside the hotkeys, written atomically, checked."""

from __future__ import annotations

import math
import os
import re
from pathlib import Path

import pytest

from ocu.console.poses import PoseError, PoseStore, check_name

JOINTS = ("waist", "shoulder", "elbow", "neck")
LIMITS = {j: (-math.radians(150.0), math.radians(150.0)) for j in JOINTS}
BUILTIN = {"stow": dict.fromkeys(JOINTS, 0.0)}
POSE = {"waist": 0.1, "shoulder": 0.5, "elbow": 1.0, "neck": -0.2}


def store(path: Path) -> PoseStore:
    return PoseStore(BUILTIN, JOINTS, LIMITS, path)


def test_saved_poses_come_back_in_order_and_in_degrees(tmp_path: Path) -> None:
    path = tmp_path / "cfg" / "arm_poses.toml"
    poses = store(path)
    poses.save("  over the box ", POSE)
    poses.save("b-2", {**POSE, "waist": -0.3})
    text = path.read_text()
    assert '[poses."over the box"]' in text
    assert f"shoulder = {math.degrees(0.5):.4f}" in text
    again = store(path)
    assert again.error == ""
    assert again.names == ("stow", "over the box", "b-2")
    assert again.get("over the box") == pytest.approx(POSE, abs=1e-6)
    again.delete("b-2")
    assert store(path).names == ("stow", "over the box")


def test_bad_names_and_values_are_refused(tmp_path: Path) -> None:
    poses = store(tmp_path / "arm_poses.toml")
    for name, message in (
        ("", "needs a name"),
        ("x" * 41, "at most 40"),
        ("a/b", "use letters"),
        ("stow", "one of the robot's poses"),
    ):
        with pytest.raises(PoseError, match=message):
            poses.save(name, POSE)
    with pytest.raises(PoseError, match=r"elbow 171\.9° is outside its limits"):
        poses.save("far", {**POSE, "elbow": 3.0})
    with pytest.raises(PoseError, match="not all known"):
        poses.save("part", {"waist": 0.0})
    with pytest.raises(PoseError, match="cannot be deleted"):
        poses.delete("stow")
    with pytest.raises(PoseError, match="no stored pose 'nope'; known: stow"):
        poses.get("nope")
    assert check_name(" ok_1 ") == "ok_1"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("poses = 3", "poses must be tables"),
        ("[poses.a]\nwaist = 0\n", r"'a': no angle for shoulder, elbow, neck"),
        ("[poses.a]\nknee = 0\n", r"unknown joint 'knee'; the arm's joints are waist"),
        ("[poses.a]\nwaist = 'x'\nshoulder = 0\nelbow = 0\nneck = 0\n", "must be a number"),
        ("[other]\n", "unknown table 'other'"),
        ("[poses.stow]\nwaist = 0\nshoulder = 0\nelbow = 0\nneck = 0\n", "rename it"),
        ("[poses\n", "not valid TOML"),
    ],
)
def test_a_bad_file_is_refused_with_the_reason_and_the_robots_poses_stay(
    tmp_path: Path, text: str, message: str
) -> None:
    path = tmp_path / "arm_poses.toml"
    path.write_text(text)
    poses = store(path)
    assert re.search(message, poses.error)
    assert str(path) in poses.error
    assert poses.names == ("stow",)


def test_the_file_is_replaced_whole(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A write that fails half-way (disk full, killed) leaves the old file as it was."""
    path = tmp_path / "arm_poses.toml"
    poses = store(path)
    poses.save("first", POSE)
    before = path.read_text()

    def broken_replace(src: str | os.PathLike[str], dst: str | os.PathLike[str]) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", broken_replace)
    with pytest.raises(PoseError, match=r"cannot write .*No space left"):
        poses.save("second", POSE)
    assert path.read_text() == before
    assert poses.names == ("stow", "first")
    assert [p.name for p in tmp_path.iterdir()] == ["arm_poses.toml"]  # no temporary left
