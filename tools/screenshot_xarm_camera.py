"""docs/screenshots/xarm_camera.png: the console on the xArm simulator with the scene camera
on its gripper (`ocu --profile xarm1s --camera scene`), tracking the red disc, no display.

    .venv/bin/python tools/screenshot_xarm_camera.py [OUT.png] [--seconds 6]

Qt on its offscreen platform, the 3D dock through OSMesa or EGL (ocu.render.platform), the
window layout the default one (settings in a temporary folder). After a second the object is
clicked in the Video dock (as the operator would, with Track on); the picture is taken
`--seconds` later, while the arm follows it.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ocu.render.platform import configure_gl_platform

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n", 1)[0])
    parser.add_argument(
        "out", nargs="?", type=Path, default=ROOT / "docs/screenshots/xarm_camera.png"
    )
    parser.add_argument("--seconds", type=float, default=6.0)
    parser.add_argument("--size", default="1600x1000")
    args = parser.parse_args()
    os.environ["QT_QPA_PLATFORM"] = "offscreen"
    configure_gl_platform("offscreen")

    from PySide6.QtCore import QSettings, QTimer
    from PySide6.QtWidgets import QApplication

    from ocu.control.reach_tracking import ServoModel
    from ocu.hardware.xarm import XARM_CAPABILITIES
    from ocu.hotkeys import load_key_map
    from ocu.profile.xarm import load_xarm_profile
    from ocu.profile.xarm_robot import xarm_robot_profile
    from ocu.windows.cameras import LocalCameras, SceneLinks, add_cameras
    from ocu.windows.main_window import MainWindow

    app = QApplication.instance() or QApplication(sys.argv[:1])
    assert isinstance(app, QApplication)
    arm = load_xarm_profile("xarm1s")
    profile = add_cameras(xarm_robot_profile(arm), ["scene"], tool_link="tool0")
    links = SceneLinks(arm, profile)
    servo = ServoModel(arm.servo.damping_ratio, arm.servo.natural_frequency_rad_s)
    cameras = LocalCameras(profile, ["scene"], scene=links, servo=servo)
    width, height = (int(v) for v in args.size.split("x"))
    with tempfile.TemporaryDirectory(prefix="ocu-shot-") as config:
        settings = QSettings(str(Path(config) / "ocu.ini"), QSettings.Format.IniFormat)
        window = MainWindow(
            profile,
            links.make_link,
            links.where,
            settings,
            load_key_map(profile),
            hardware_for=links.hardware_for,
            capabilities=XARM_CAPABILITIES | {"cameras"},
        )
        window.resize(width, height)
        window.show()
        cameras.attach(window)
        panel = window.video_panel
        problems: list[str] = []

        def click() -> None:
            camera = links.scene_camera()
            seen = camera.project(camera.object_at(camera.clock()))
            if seen is None:
                problems.append("the object is not in view")
                return
            size = camera.calibration.size_px
            panel.set_track_mode(True)
            if not panel.start_tracking_at(0, seen[0] / size[0], seen[1] / size[1]):
                problems.append(panel.message_label.text())

        def shoot() -> None:
            if not window.grab().save(str(args.out)):
                problems.append(f"cannot write {args.out}")
            app.quit()

        QTimer.singleShot(1000, click)
        QTimer.singleShot(int((1.0 + args.seconds) * 1000), shoot)
        app.exec()
        window.shutdown()
        cameras.stop()
        links.close()
    for problem in problems:
        print(f"screenshot: {problem}", file=sys.stderr)
    if not problems:
        print(f"wrote {args.out}")
    return 1 if problems else 0


if __name__ == "__main__":
    raise SystemExit(main())
