"""`ocu` refuses a bad profile, key map or config directory with one clear line, before any
window; a settings file it cannot read or write costs the layout, never the file."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest

from ocu.profile import default_profile_path
from ocu.sim.simulator import RobotSimulator
from ocu.windows.settings_file import ini_problem
from tests.windows.console_fixtures import RUN_TIMEOUT_S, run_ocu, sim

__all__ = ["sim"]  # fixtures used below

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


def test_a_config_dir_that_is_a_file_is_refused(tmp_path: Path) -> None:
    config = tmp_path / "cfg"
    config.write_text("not a folder")
    result = run_ocu(tmp_path, "--config-dir", str(config))
    assert result.returncode == 2
    _assert_one_line(result.stderr, f"config directory {config} is a file, not a folder")
    below = config / "ocu"
    result = run_ocu(tmp_path, "--config-dir", str(below))
    assert result.returncode == 2
    _assert_one_line(result.stderr, f"config directory {below} cannot be made: {config} is a file")
    assert config.read_text() == "not a folder"


JUNK_INI = b"\x89PNG\r\n\x1a\n\x00\x00 not the layout \xff\xfe"
LAYOUT = "main_window"  # the group ocu.ini keeps the window layout in


def test_an_unreadable_ocu_ini_is_kept_aside_not_overwritten(tmp_path: Path) -> None:
    config = tmp_path / "cfg"  # run_ocu's config dir
    config.mkdir()
    (config / "ocu.ini").write_bytes(JUNK_INI)
    result = run_ocu(tmp_path, "--quit-after", "1")
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    assert (config / "ocu.ini.unreadable").read_bytes() == JUNK_INI
    assert (
        f"{config / 'ocu.ini'} cannot be read (not text (not UTF-8)): kept as ocu.ini.unreadable"
        in (result.stderr)
    )
    assert f"[{LAYOUT}]" in (config / "ocu.ini").read_text()  # the new layout was saved
    assert ini_problem(config / "ocu.ini") is None  # and is read at the next start


def run_ocu_unprivileged(folder: Path, *args: str) -> subprocess.CompletedProcess[str]:
    """`python -m ocu ARGS` offscreen as a user whom a folder's mode refuses a write (as root:
    root without the capabilities that override file modes, through setpriv, so the checkout
    and its venv stay readable wherever they are, /root included; otherwise as the current
    user, for whom chmod does it)."""
    env = {
        **os.environ,
        "QT_QPA_PLATFORM": "offscreen",
        "OCU_RECORDINGS_DIR": str(folder / "recordings"),
        "HOME": str(folder / "home"),
        "XDG_RUNTIME_DIR": str(folder / "home"),
    }
    prefix: list[str] = []
    if os.geteuid() == 0:
        setpriv = shutil.which("setpriv")
        if setpriv is None:
            pytest.skip("running as root without setpriv: no user to be refused a write")
        prefix = [setpriv, "--bounding-set", "-dac_override,-dac_read_search,-fowner", "--"]
    return subprocess.run(
        [*prefix, sys.executable, "-m", "ocu", *args],
        env=env,
        capture_output=True,
        text=True,
        timeout=RUN_TIMEOUT_S,
        check=False,
        cwd=folder,
    )


@pytest.fixture
def open_folder() -> Iterator[Path]:
    """A folder everyone may enter and write (pytest's tmp_path is the user's own)."""
    folder = Path(tempfile.mkdtemp(prefix="ocu-config-test-"))
    folder.chmod(0o777)
    for name in ("recordings", "home"):
        (folder / name).mkdir(mode=0o777)
        (folder / name).chmod(0o777)
    yield folder
    for path in folder.rglob("*"):
        if path.is_dir():
            path.chmod(0o755)
    shutil.rmtree(folder)


@pytest.mark.parametrize("ini", [b"[main_window]\nx=1\n", JUNK_INI], ids=["layout", "junk"])
def test_a_read_only_config_dir_runs_says_so_and_writes_nothing(
    open_folder: Path, sim: RobotSimulator, ini: bytes
) -> None:
    config = open_folder / "cfg"
    config.mkdir()
    (config / "ocu.ini").write_bytes(ini)
    config.chmod(0o555)
    host, port = sim.address  # the simulator in this process: nothing else to start
    result = run_ocu_unprivileged(
        open_folder, "--robot", f"{host}:{port}", "--config-dir", str(config), "--quit-after", "1"
    )
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    assert sorted(p.name for p in config.iterdir()) == ["ocu.ini"]
    assert (config / "ocu.ini").read_bytes() == ini
    if ini == JUNK_INI:
        assert "cannot be read (not text (not UTF-8)) nor moved aside" in result.stderr
    else:
        assert f"config directory {config} cannot be written" in result.stderr
    assert "the window layout is not saved this session" in result.stderr
    assert "window layout not saved (" in result.stderr  # said again at exit


@pytest.mark.parametrize(
    ("value", "expected"),
    [("2", "2 Hz is outside 5-1000 Hz"), ("fast", "not a number: 'fast'")],
)
def test_a_control_rate_it_cannot_keep_is_refused(value: str, expected: str) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "ocu", "--control-hz", value],
        capture_output=True,
        text=True,
        timeout=RUN_TIMEOUT_S,
        check=False,
    )
    assert done.returncode == 2
    assert "Traceback" not in done.stderr
    assert f"argument --control-hz: {expected}" in done.stderr


@pytest.mark.parametrize(
    "extra", [["--replay", "x.mcap"], ["--live", "127.0.0.1:0"], ["--camera", "0"]]
)
def test_the_core_process_refuses_what_it_does_not_run_yet(extra: list[str]) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "ocu", "--core-process", *extra, "--quit-after", "5"],
        capture_output=True,
        text=True,
        timeout=RUN_TIMEOUT_S,
        check=False,
    )
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr
    assert "--core-process runs the Engineer's, a UR's and the xArm's consoles" in done.stderr
