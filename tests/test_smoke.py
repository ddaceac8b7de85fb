"""`ocu` as a program: starts, runs and quits by itself (pyqtgraph's example-smoke habit)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from ocu.profile import RobotProfile
from ocu.sim.simulator import RobotSimulator

RUN_TIMEOUT_S = 60


def run_ocu(tmp_path: Path, *args: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "QT_QPA_PLATFORM": "offscreen", "OCU_CONFIG_DIR": str(tmp_path / "cfg")}
    return subprocess.run(
        [sys.executable, "-m", "ocu", *args],
        env=env,
        capture_output=True,
        text=True,
        timeout=RUN_TIMEOUT_S,
        check=False,
    )


def qt_complaints(stderr: str) -> list[str]:
    """Lines that are not our log lines: Qt warnings, tracebacks."""
    return [
        line
        for line in stderr.splitlines()
        if line.strip() and not line[:4].isdigit() and "OpenGL_accelerate" not in line
    ]


def test_ocu_starts_its_simulator_and_quits_by_itself(tmp_path: Path) -> None:
    result = run_ocu(tmp_path, "--quit-after", "2")
    assert result.returncode == 0, result.stderr
    assert "link connected" in result.stderr
    assert "zeros sent last" in result.stderr
    assert qt_complaints(result.stderr) == []
    assert (tmp_path / "cfg" / "ocu.ini").exists()  # the layout was remembered


def test_ocu_quitting_by_itself_leaves_zeros_last_on_the_wire(
    tmp_path: Path, profile: RobotProfile
) -> None:
    with RobotSimulator(profile, telemetry_hz=5.0, video_fps=0.0) as sim:
        host, port = sim.address
        result = run_ocu(tmp_path, "--robot", f"{host}:{port}", "--quit-after", "1.5")
        assert result.returncode == 0, result.stderr
        received = sim.received_commands()
    assert len(received) >= profile.link.estop_repeats
    assert all(not any(r.packet.axes) for r in received[-profile.link.estop_repeats :])
    assert qt_complaints(result.stderr) == []


def test_bad_key_map_is_refused_before_any_window(tmp_path: Path) -> None:
    keys = tmp_path / "keys.toml"
    keys.write_text('[hold]\nW = "tail +"\n', encoding="utf-8")
    result = run_ocu(tmp_path, "--keys", str(keys))
    assert result.returncode == 2
    assert "unknown channel 'tail'" in result.stderr
