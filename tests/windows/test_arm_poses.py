"""The operator's stored poses in the whole console: a bad one is named in the Events dock and
the others are offered; a name is typed without Space (the e-stop), and saving keeps the file."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

from PySide6.QtCore import QSettings, Qt
from PySide6.QtTest import QTest
from pytestqt.qtbot import QtBot

from ocu.profile import RobotProfile
from ocu.sim.simulator import RobotSimulator
from ocu.windows.arm import NAME_HINT
from tests.windows.console_fixtures import (
    DEADLINE_MS,
    ConsoleFactory,
    make_console,
    settings,
    sim,
    wait_sim,
    wait_zeros,
)

__all__ = ["make_console", "settings", "sim"]  # fixtures used below


def test_a_bad_pose_is_named_the_others_kept_and_names_typed_without_space(
    make_console: ConsoleFactory,
    sim: RobotSimulator,
    profile: RobotProfile,
    settings: QSettings,
    qtbot: QtBot,
) -> None:
    assert profile.arm is not None
    ready = {j: math.degrees(a) for j, a in profile.arm.poses["ready"].items()}
    path = Path(settings.fileName()).parent / "arm_poses.toml"
    waist_limit_deg = math.degrees(profile.motors["waist"].limits_rad[1])  # type: ignore[index]
    text = ""
    for name, waist in (("a", 10.0), ("b", waist_limit_deg + 5.0), ("c", 20.0), ("d", 30.0)):
        text += f"[poses.{name}]\n"
        text += "".join(f"{j} = {waist if j == 'waist' else v}\n" for j, v in ready.items())
    path.write_text(text)
    before = tomllib.loads(text)

    console = make_console(sim)
    panel = console.arm_panel
    assert panel is not None
    offered = [panel.pose_list.item(i).text() for i in range(panel.pose_list.count())]
    assert offered[-3:] == ["a", "c", "d"]
    events = [console.event_log.item(i).text() for i in range(console.event_log.count())]
    named = [e for e in events if "stored arm poses" in e and "'b'" in e]
    assert named, events
    assert str(path) in named[0]
    assert "outside its limits" in named[0]

    # A name typed in the box: Space stops the robot and types nothing; '_' joins words.
    console.velocity_panel.sliders["neck"].setValue(500)
    wait_sim(qtbot, sim, lambda s: s.velocities["neck"] > 0, "neck moving from the slider")
    box = panel.name_box
    box.setFocus()
    qtbot.waitUntil(box.hasFocus, timeout=DEADLINE_MS)
    QTest.keyClicks(box, "over")
    QTest.keyClick(box, Qt.Key.Key_Space)
    wait_zeros(qtbot, sim, "stopped by Space typed into the pose name box")
    QTest.keyClicks(box, "_the_box")
    assert box.text() == "over_the_box"
    assert NAME_HINT in [label.text() for label in panel.findChildren(type(panel.message_label))]

    panel.save_button.click()
    assert box.text() == "", panel.message_label.text()
    after = tomllib.loads(path.read_text())
    assert set(after["poses"].pop("over_the_box")) == set(ready)
    assert after == before  # every pose of the file, the bad one as it was
