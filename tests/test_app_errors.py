"""`ocu` refuses a bad profile or key map file with one clear line, before any window."""

from __future__ import annotations

from pathlib import Path

import pytest

from ocu.profile import default_profile_path
from tests.windows.console_fixtures import run_ocu

NOT_UTF8 = b'[hold]\nK = "waist \xff"\n'


def _assert_one_line(stderr: str, expected: str) -> None:
    assert "Traceback" not in stderr
    assert stderr.splitlines() == [f"ocu: error: {expected}"]


@pytest.mark.parametrize("where", ["--keys", "config-dir"])
def test_non_utf8_key_map(tmp_path: Path, where: str) -> None:
    if where == "--keys":
        keys = tmp_path / "bad.toml"
        args: tuple[str, ...] = ("--keys", str(keys))
    else:
        keys = tmp_path / "cfg" / "hotkeys.toml"  # run_ocu's config dir
        args = ()
    keys.parent.mkdir(parents=True, exist_ok=True)
    keys.write_bytes(NOT_UTF8)
    result = run_ocu(tmp_path, *args)
    assert result.returncode == 2
    _assert_one_line(
        result.stderr,
        f"{keys}: not UTF-8 text: 'utf-8' codec can't decode byte 0xff in position 18: "
        "invalid start byte",
    )


def test_misspelt_key_map_entry(tmp_path: Path) -> None:
    keys = tmp_path / "keys.toml"
    keys.write_text("[options]\nfine_factr = 0.5\n", encoding="utf-8")
    result = run_ocu(tmp_path, "--keys", str(keys))
    assert result.returncode == 2
    _assert_one_line(
        result.stderr, f"{keys}: options.fine_factr: unknown option; did you mean 'fine_factor'?"
    )


@pytest.mark.parametrize(
    ("content", "expected"),
    [
        (b'name = "Engineer \xff"\n', "not UTF-8 text: "),
        (
            default_profile_path().read_bytes().replace(b"send_rate_hz =", b"sned_rate_hz ="),
            "profile.link.sned_rate_hz: unknown key; did you mean 'send_rate_hz'?",
        ),
    ],
    ids=["not-utf8", "misspelt"],
)
def test_bad_profile(tmp_path: Path, content: bytes, expected: str) -> None:
    profile = tmp_path / "robot.toml"
    profile.write_bytes(content)
    result = run_ocu(tmp_path, "--profile", str(profile))
    assert result.returncode == 2
    assert "Traceback" not in result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1
    assert lines[0].startswith("ocu: error: ")
    assert expected in lines[0]
