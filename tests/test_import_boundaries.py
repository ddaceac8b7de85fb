"""The codecs, the profile and the control logic import no Qt (STYLE.md, napari habit)."""

from __future__ import annotations

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
