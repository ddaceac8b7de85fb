"""The operator's stored poses: a TOML file beside the hotkeys, written atomically, checked."""

from __future__ import annotations

import math
import os
import re
import tomllib
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
    poses.save("  over the box ", POSE)  # typed into the file by hand; the Arm dock uses _
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


GOOD = "[poses.good]\nwaist = 10\nshoulder = 20\nelbow = 30\nneck = 40\n"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[poses.a]\nwaist = 0\n", r"'a': no angle for shoulder, elbow, neck"),
        ("[poses.a]\nknee = 0\n", r"'a': unknown joint 'knee'; the arm's joints are waist"),
        ("[poses.a]\nwaist = 'x'\nshoulder = 0\nelbow = 0\nneck = 0\n", "must be a number"),
        ("[poses.a]\nwaist = 0\nshoulder = 0\nelbow = 171\nneck = 0\n", "outside its limits"),
        ("[poses.stow]\nwaist = 0\nshoulder = 0\nelbow = 0\nneck = 0\n", "rename it"),
        ('[poses."a/b"]\nwaist = 0\nshoulder = 0\nelbow = 0\nneck = 0\n', "use letters"),
        ("[poses]\na = 3\n", "'a': must be a table"),
    ],
)
def test_a_bad_pose_is_named_the_others_are_offered_and_it_is_kept_on_save(
    tmp_path: Path, text: str, message: str
) -> None:
    path = tmp_path / "arm_poses.toml"
    path.write_text(GOOD + text)
    before = tomllib.loads(path.read_text())
    poses = store(path)
    assert poses.names == ("stow", "good")
    assert len(poses.problems) == 1
    assert re.search(message, poses.problems[0])
    assert str(path) in poses.error
    # Saving keeps every pose of the file, the unusable one as it was.
    poses.save("new_one", POSE)
    after = tomllib.loads(path.read_text())
    assert after["poses"].pop("new_one") == pytest.approx(
        {j: math.degrees(v) for j, v in POSE.items()}, abs=1e-4
    )
    assert after == before
    again = store(path)
    assert again.names == ("stow", "good", "new_one")
    assert again.problems == poses.problems


def test_one_pose_outside_a_limit_leaves_the_other_three(tmp_path: Path) -> None:
    path = tmp_path / "arm_poses.toml"
    angles = "shoulder = 20\nelbow = 30\nneck = 40\n"
    path.write_text(
        "".join(
            f"[poses.{n}]\nwaist = {w}\n{angles}"
            for n, w in (("a", 10), ("b", 170), ("c", 30), ("d", 40))
        )
    )
    poses = store(path)
    assert poses.names == ("stow", "a", "c", "d")
    assert poses.problems == (
        f"{path}: 'b': waist 170.0° is outside its limits [-150.0°, 150.0°]; not offered",
    )
    with pytest.raises(PoseError, match=r"'b' cannot be used: 'b': waist 170\.0° is outside"):
        poses.get("b")
    with pytest.raises(PoseError, match="holds a pose 'b' that cannot be used"):
        poses.save("b", POSE)
    poses.save("e", POSE)
    poses.delete("a")
    assert store(path).names == ("stow", "c", "d", "e")
    assert tomllib.loads(path.read_text())["poses"]["b"]["waist"] == 170


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"poses = 3", "poses must be tables"),
        (b"[other]\n", "unknown table 'other'"),
        (b"[poses\n", "not valid TOML"),
        (b"[poses.a]\nwaist = '\xff'\n", "not valid TOML"),
    ],
    ids=["not-tables", "unknown-table", "not-toml", "not-utf8"],
)
def test_a_file_that_cannot_be_read_is_never_written_over(
    tmp_path: Path, content: bytes, message: str
) -> None:
    path = tmp_path / "arm_poses.toml"
    path.write_bytes(content)
    poses = store(path)
    assert re.search(message, poses.error)
    assert str(path) in poses.error
    assert poses.names == ("stow",)
    with pytest.raises(PoseError, match=f"not saved: .*{message}.*not written over"):
        poses.save("new", POSE)
    assert path.read_bytes() == content
    # Fixed meanwhile (in an editor): the next save reads it again and keeps what it holds.
    path.write_text(GOOD)
    poses.save("new", POSE)
    assert list(poses.names) == ["stow", "good", "new"]
    assert store(path).names == ("stow", "good", "new")


def test_any_value_of_a_pose_that_cannot_be_used_is_written_back_as_it_was(
    tmp_path: Path,
) -> None:
    path = tmp_path / "arm_poses.toml"
    odd = (
        '[poses.odd]\nwaist = "a \\"quoted\\" \\u007f\\n line ü"\nshoulder = true\n'
        "elbow = [1, 2.5, inf, -inf]\nneck = { a = 1979-05-27T07:32:00Z, b = 07:32:00 }\n"
        "knee = 1979-05-27\nhip = nan\n"
    )
    path.write_text(GOOD + odd)
    before = tomllib.loads(path.read_text())
    poses = store(path)
    poses.save("new", POSE)
    after = tomllib.loads(path.read_text())
    del after["poses"]["new"]
    assert math.isnan(after["poses"]["odd"].pop("hip"))
    assert math.isnan(before["poses"]["odd"].pop("hip"))
    assert after == before


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
