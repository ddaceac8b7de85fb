"""The codecs, the profile and the control logic import no Qt (STYLE.md, napari habit)."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]

PURE_MODULES = (
    "ocu.protocol",
    "ocu.profile",
    "ocu.control.commands",
    "ocu.control.position",
    "ocu.console.model",
    "ocu.hotkeys",
    "ocu.console.robot",
    "ocu.records",
    "ocu.link.live",
    "ocu.link.receiver",
    "ocu.net.loop",
    "ocu.record.replay_link",
    "ocu.sim.simulator",
    "ocu.model.tree",
)

_CHECK = f"""
import importlib
import sys

for name in {PURE_MODULES!r}:
    importlib.import_module(name)
qt = sorted(
    name
    for name in sys.modules
    if name.split(".")[0].startswith(("PySide6", "pyqtgraph", "shiboken6"))
)
print(",".join(qt))
"""


def test_pure_modules_import_no_qt() -> None:
    result = subprocess.run(
        [sys.executable, "-c", _CHECK],
        capture_output=True,
        text=True,
        check=False,
        timeout=60,
        cwd=REPO_ROOT,
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "", f"Qt modules imported: {result.stdout.strip()}"


def test_check_would_see_qt() -> None:
    # The subprocess check must be able to fail: importing pyqtgraph shows up in it.
    code = _CHECK.replace("importlib.import_module(name)", "importlib.import_module('pyqtgraph')")
    result = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        check=False,
        timeout=60,
        cwd=REPO_ROOT,
    )
    assert result.returncode == 0, result.stderr
    assert "pyqtgraph" in result.stdout


def test_import_linter_contracts_kept() -> None:
    lint_imports = Path(sys.executable).parent / "lint-imports"
    assert lint_imports.exists(), f"{lint_imports} not installed"
    result = subprocess.run(
        [str(lint_imports), "--no-cache"],
        capture_output=True,
        text=True,
        check=False,
        timeout=120,
        cwd=REPO_ROOT,
    )
    assert result.returncode == 0, result.stdout + result.stderr


# The core and the views speak the neutral records (ocu.records), never the Engineer's wire
# (also an import-linter contract in pyproject.toml, run by `./dev test`).
PROTOCOL_FREE = ("records", "control", "console", "core", "widgets", "windows", "qt", "headless")


def _protocol_imports(path: Path) -> list[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    found: list[str] = []
    for node in ast.walk(tree):
        names = (
            [alias.name for alias in node.names]
            if isinstance(node, ast.Import)
            else [node.module or ""]
            if isinstance(node, ast.ImportFrom)
            else []
        )
        found.extend(n for n in names if n == "ocu.protocol" or n.startswith("ocu.protocol."))
    return found


def _modules(package: str) -> list[Path]:
    root = REPO_ROOT / "ocu"
    single = root / f"{package}.py"
    return [single] if single.exists() else sorted((root / package).rglob("*.py"))


def test_core_and_views_import_nothing_of_the_protocol() -> None:
    offenders = {
        str(path.relative_to(REPO_ROOT)): imports
        for package in PROTOCOL_FREE
        for path in _modules(package)
        if (imports := _protocol_imports(path))
    }
    assert offenders == {}


def test_protocol_check_would_see_an_import() -> None:
    # The check must be able to fail: the live link does speak the protocol.
    assert _protocol_imports(REPO_ROOT / "ocu" / "link" / "live.py")


# Issue 21: no module of the program over this many lines (split along a line a newcomer can
# see from the folder names).
MAX_MODULE_LINES = 700


def module_lengths(root: Path) -> dict[str, int]:
    """Each .py file below `root` (relative to it) and its number of lines."""
    return {
        str(path.relative_to(root)): len(path.read_text(encoding="utf-8").splitlines())
        for path in sorted(root.rglob("*.py"))
    }


def test_no_module_of_the_program_is_over_700_lines() -> None:
    lengths = module_lengths(REPO_ROOT / "ocu")
    assert len(lengths) > 100  # the walk found the program
    too_long = {name: count for name, count in lengths.items() if count > MAX_MODULE_LINES}
    assert not too_long, f"over {MAX_MODULE_LINES} lines: {too_long}"


def test_the_length_check_would_see_a_long_module(tmp_path: Path) -> None:
    (tmp_path / "long.py").write_text("x = 1\n" * (MAX_MODULE_LINES + 1), encoding="utf-8")
    (tmp_path / "short.py").write_text("x = 1\n", encoding="utf-8")
    assert module_lengths(tmp_path) == {"long.py": MAX_MODULE_LINES + 1, "short.py": 1}
