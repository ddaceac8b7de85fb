"""The window builds the views the hardware's capabilities ask for, and no others.

A robot without cameras and without a chassis: the shipped Engineer profile with its drive
channels and track motors removed, read by the profile's own parser, and its cameras taken
out after (the parser insists on `link.camera_names`: the vendor's wire always names its
cameras - the profile split of issue 21 lifts that); its key map and pad mapping are the
shipped ones without the drive entries. The
window is real (offscreen) and so is the simulator it connects to over UDP.
"""

from __future__ import annotations

import tomllib
from collections.abc import Iterator
from dataclasses import replace

import pytest
from PySide6.QtCore import QSettings
from PySide6.QtWidgets import QApplication, QDockWidget
from pytestqt.qtbot import QtBot

from ocu.core.hardware import HardwareComponent
from ocu.gamepad.mapping import default_pad_map_path, parse_pad_mapping
from ocu.hardware.engineer import engineer_capabilities, engineer_component
from ocu.hotkeys import default_key_map_path, parse_key_map
from ocu.link.base import Link
from ocu.link.live import UdpLink
from ocu.profile import RobotProfile
from ocu.profile.parse import load_profile_data, parse_profile
from ocu.records import LinkState
from ocu.sim.simulator import RobotSimulator
from ocu.widgets.map_view import MapPanel
from ocu.widgets.video import VideoPanel
from ocu.windows.main_window import MainWindow, MissingCapabilityError
from tests.windows.console_fixtures import DEADLINE_MS, wait_sim

DRIVE = ("drive_linear", "drive_turn")


@pytest.fixture(scope="module")
def armless_cart() -> RobotProfile:
    """The shipped profile without cameras and without a chassis that drives."""
    data = load_profile_data()
    for channel in DRIVE:
        del data["channels"][channel]
    for motor in ("left_track", "right_track"):
        del data["motors"][motor]
    profile = replace(parse_profile(data, "engineer.toml without drive"), cameras=())
    assert profile.drive_channels is None
    return profile


def _without_drive(table: dict[str, object]) -> dict[str, object]:
    return {
        key: value
        for key, value in table.items()
        if not (isinstance(value, str) and value.split()[0] in DRIVE)
    }


@pytest.fixture
def windows() -> Iterator[list[MainWindow]]:
    """The windows a test built, shut down after it."""
    built: list[MainWindow] = []
    yield built
    for window in built:
        window.shutdown()
    QApplication.processEvents()


def _window(
    built: list[MainWindow],
    qtbot: QtBot,
    profile: RobotProfile,
    *,
    sim: RobotSimulator,
    settings: QSettings,
    capabilities: frozenset[str] | None = None,
) -> MainWindow:
    keys = tomllib.loads(default_key_map_path().read_text(encoding="utf-8"))
    keys["hold"] = _without_drive(keys["hold"])
    pad = tomllib.loads(default_pad_map_path().read_text(encoding="utf-8"))
    pad["axes"] = _without_drive(pad["axes"])

    def link_factory() -> Link:
        return UdpLink(profile, sim.address)

    window = MainWindow(
        profile,
        link_factory,
        "simulator",
        settings,
        parse_key_map(keys, profile),
        pad_mapping=parse_pad_mapping(pad, profile),
        capabilities=capabilities,
    )
    qtbot.addWidget(window)
    built.append(window)
    window.show()
    qtbot.waitUntil(lambda: window.link_status.state == LinkState.CONNECTED, timeout=DEADLINE_MS)
    return window


@pytest.fixture
def cart_sim(armless_cart: RobotProfile) -> Iterator[RobotSimulator]:
    simulator = RobotSimulator(armless_cart, telemetry_hz=10.0, video_fps=0.0)
    simulator.start()
    yield simulator
    simulator.stop()


def _dock_names(window: MainWindow) -> set[str]:
    return {dock.objectName() for dock in window.findChildren(QDockWidget)}


def test_no_cameras_no_chassis_no_video_dock_no_map_dock(
    windows: list[MainWindow],
    qtbot: QtBot,
    armless_cart: RobotProfile,
    cart_sim: RobotSimulator,
    settings: QSettings,
) -> None:
    window = _window(windows, qtbot, armless_cart, sim=cart_sim, settings=settings)
    assert window.capabilities == {"torch", "calibration", "arm", "range_scan", "battery", "imu"}
    names = _dock_names(window)
    assert "video_dock" not in names
    assert "map_dock" not in names
    assert {"velocity_dock", "joint_position_dock", "arm_dock"} <= names
    assert not window.findChildren(VideoPanel)
    assert not window.findChildren(MapPanel)
    with pytest.raises(MissingCapabilityError, match="'cameras'"):
        _ = window.video_panel
    with pytest.raises(MissingCapabilityError, match="'drive'"):
        _ = window.map_dock
    # The component the control thread reads and writes says the same.
    hardware = window.control.hardware
    assert isinstance(hardware, HardwareComponent)
    assert not hardware.has("cameras")
    assert not hardware.has("drive")
    # The window still commands what the robot has: the waist moves.
    window.model.set_velocity("waist", 0.3)
    wait_sim(qtbot, cart_sim, lambda s: s.velocities["waist"] > 0.1, "the waist moving")
    window.model.emergency_stop("test")
    wait_sim(qtbot, cart_sim, lambda s: s.all_stopped, "all stopped")
    # The layout of a window without the two docks saves and restores.
    window.save_layout()
    assert window.restore_layout()


def test_the_torch_control_only_with_a_torch(
    windows: list[MainWindow],
    qtbot: QtBot,
    armless_cart: RobotProfile,
    cart_sim: RobotSimulator,
    settings: QSettings,
) -> None:
    window = _window(
        windows,
        qtbot,
        armless_cart,
        sim=cart_sim,
        settings=settings,
        capabilities=engineer_capabilities(armless_cart, extension=False) - {"torch"},
    )
    panel = window.velocity_panel
    assert not panel.torch_box.isVisibleTo(window)
    assert not panel.torch_box.isEnabled()
    assert not panel.headlight.isVisibleTo(window)


def test_the_engineer_has_every_view(
    windows: list[MainWindow],
    qtbot: QtBot,
    profile: RobotProfile,
    sim: RobotSimulator,
    settings: QSettings,
) -> None:
    window = MainWindow(profile, lambda: UdpLink(profile, sim.address), "simulator", settings)
    qtbot.addWidget(window)
    windows.append(window)
    window.show()
    qtbot.waitUntil(lambda: window.link_status.state == LinkState.CONNECTED, timeout=DEADLINE_MS)
    assert {"video_dock", "map_dock"} <= _dock_names(window)
    assert window.velocity_panel.torch_box.isVisibleTo(window)
    assert isinstance(window.video_panel, VideoPanel)
    hardware = window.control.hardware
    assert isinstance(hardware, HardwareComponent)
    assert hardware.capabilities == engineer_component(hardware.link).capabilities
    assert {"cameras", "drive", "torch", "arm"} <= hardware.capabilities
