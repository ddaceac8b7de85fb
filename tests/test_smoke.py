"""`ocu` as a program: starts, runs and quits by itself (pyqtgraph's example-smoke habit)."""

from __future__ import annotations

from pathlib import Path

from ocu.profile import RobotProfile
from ocu.sim.simulator import RobotSimulator
from tests.windows.console_fixtures import qt_complaints, run_ocu


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


def test_window_screenshot_renders_the_whole_console(tmp_path: Path) -> None:
    from PIL import Image

    out = tmp_path / "console.png"
    result = run_ocu(
        tmp_path,
        "screenshot",
        "--window",
        str(out),
        "--seconds",
        "1.5",
        "--size",
        "1280x800",
        "--joints",
        "waist=20",
    )
    assert result.returncode == 0, result.stderr
    assert qt_complaints(result.stderr) == []
    with Image.open(out) as image:
        assert image.size == (1280, 800)
        assert len(image.convert("RGB").getcolors(1 << 20) or []) > 500  # docks, 3D, text
    # The model-only screenshot is still `ocu screenshot OUT.png`.
    model = tmp_path / "model.png"
    result = run_ocu(tmp_path, "screenshot", str(model), "--size", "320x240")
    assert result.returncode == 0, result.stderr
    with Image.open(model) as image:
        assert image.size == (320, 240)
    bad = run_ocu(tmp_path, "screenshot", "--window", str(out), "--joints", "knee=10")
    assert bad.returncode == 1
    assert "knee=10" in bad.stderr
