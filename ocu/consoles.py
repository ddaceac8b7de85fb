"""Starting each console window of `ocu`: on the Engineer (the built-in simulator or a robot),
on a UR arm, on an arm window's hardware (the xArm), on a recording; the layout's settings
file and the LIVE indicator they share. `ocu.app` parses the command line and picks one.
"""

from __future__ import annotations

import contextlib
import logging
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from ocu.core.manager import DEFAULT_RATE_HZ as DEFAULT_CONTROL_HZ
from ocu.lifecycle import last_zeros_guard, run_window
from ocu.live.options import serve, serve_console, serving
from ocu.profile import RobotProfile
from ocu.profile.ur import UrArmProfile
from ocu.windows.settings_file import SETTINGS_FILE

if TYPE_CHECKING:
    from PySide6.QtCore import QSettings

    from ocu.core.hardware import HardwareComponent
    from ocu.core_process import CoreSpec
    from ocu.gamepad.mapping import PadMapping
    from ocu.hotkeys import KeyMap
    from ocu.link.base import Link
    from ocu.live.server import LiveServer
    from ocu.record.recorder import Recorder
    from ocu.windows.cameras import LocalCameras
    from ocu.windows.main_window import MainWindow
    from ocu.windows.settings_file import SettingsStatus

log = logging.getLogger("ocu")


def run_console(
    profile: RobotProfile,
    robot: tuple[str, int] | None,
    profile_path: str | None,
    sim_args: list[str],
    quit_after_s: float | None,
    *,
    config_dir: Path,
    key_map: KeyMap,
    record_path: Path | None = None,
    pad_mapping: PadMapping | None = None,
    control_hz: float = DEFAULT_CONTROL_HZ,
    live: LiveServer | None = None,
    cameras: LocalCameras | None = None,
    core_process: bool = False,
) -> int:
    """Start simulator (if no robot), link and window; run the Qt event loop."""
    from PySide6.QtWidgets import QApplication

    from ocu.core_process import CoreProcessError, CoreSpec
    from ocu.gamepad.calibration import CALIBRATION_FILE_NAME, CalibrationStore
    from ocu.link.base import LinkError
    from ocu.link.live import UdpLink
    from ocu.record.errors import RecordingError
    from ocu.record.recorder import Recorder
    from ocu.sim.launcher import SimulatorProcess, SimulatorProcessError, with_default_world
    from ocu.windows.main_window import MainWindow

    app = QApplication.instance() or QApplication(sys.argv[:1])
    assert isinstance(app, QApplication)
    recorder = Recorder(profile)
    if record_path is not None:
        # Before anything starts: a path that cannot be written stops here, with the reason.
        try:
            recorder.start(record_path)
        except RecordingError as err:
            log.error("%s", err)
            return 1
    simulator: SimulatorProcess | None = None
    try:
        if robot is None:
            try:
                simulator = SimulatorProcess(profile_path, with_default_world(sim_args))
            except SimulatorProcessError as err:
                log.error("%s", err)
                return 1
            robot = simulator.address
            address_text = f"simulator {robot[0]}:{robot[1]}"
        else:
            address_text = f"robot {robot[0]}:{robot[1]}"
        robot_address = robot
        try:
            # The first link is made here so a bad address fails before any window opens.
            first_link: list[Link] = [
                UdpLink(profile, robot_address, extension=True, description=address_text)
            ]
        except LinkError as err:
            log.error("%s", err)
            return 1

        def make_link() -> Link:
            if first_link:
                return first_link.pop()
            return UdpLink(profile, robot_address, extension=True, description=address_text)

        settings, settings_status = open_settings(config_dir)
        guard = contextlib.ExitStack()
        guard.enter_context(last_zeros_guard())  # the window starts the link
        # --core-process: the child builds its link to the same address (ocu.core_process).
        target = f"{robot_address[0]}:{robot_address[1]}"
        core = CoreSpec(profile, "engineer", target, options={"description": address_text})
        try:
            window = MainWindow(
                profile,
                serving(live, make_link),
                address_text,
                settings,
                key_map,
                settings_status=settings_status,
                recorder=recorder,
                pad_mapping=pad_mapping,
                pad_calibrations=CalibrationStore(config_dir / CALIBRATION_FILE_NAME),
                calibration_link=lambda raw: UdpLink(
                    raw, robot_address, extension=False, description=address_text
                ),
                control_hz=control_hz,
                core=core if core_process else None,
            )
        except CoreProcessError as err:  # the core's process did not start or answer
            guard.close()
            log.error("%s", err)
            return 1
        show_live(live, window)
        if cameras is not None:
            cameras.attach(window)
        with guard:
            return run_window(app, window, quit_after_s)
    finally:
        recorder.stop()  # after the window's shutdown: the link's closing zeros are in it
        if simulator is not None:
            simulator.stop()


def run_ur_console(
    arm: UrArmProfile,
    profile: RobotProfile,
    robot: str | None,
    quit_after_s: float | None,
    *,
    config_dir: Path,
    key_map: KeyMap,
    record_path: Path | None = None,
    pad_mapping: PadMapping | None = None,
    control_hz: float = DEFAULT_CONTROL_HZ,
    live: LiveServer | None = None,
    cameras: LocalCameras | None = None,
    core_process: bool = False,
) -> int:
    """The console on a UR arm: the controller at `robot` (HOST[:PORT_BASE]), else the UR
    simulator in this process on 127.0.0.1 (docs/ur.md); `core_process`: the control core
    and the UR link in a process of their own (docs/core-process.md)."""
    from PySide6.QtWidgets import QApplication

    from ocu.core_process import CoreSpec
    from ocu.hardware.ur import UR_CAPABILITIES, parse_host, ur_component
    from ocu.link.base import LinkError
    from ocu.link.ur import UrLink
    from ocu.record.errors import RecordingError
    from ocu.record.recorder import Recorder
    from ocu.sim.ur import UrSimulator

    app = QApplication.instance() or QApplication(sys.argv[:1])
    assert isinstance(app, QApplication)
    recorder = Recorder(profile)
    if record_path is not None:
        try:
            recorder.start(record_path)
        except RecordingError as err:
            log.error("%s", err)
            return 1
    simulator: UrSimulator | None = None
    try:
        if robot is None:
            simulator = UrSimulator(arm, host="127.0.0.1", ports=(0, 0, 0))
            simulator.start()
            host = "127.0.0.1"
            ports = tuple(simulator.ports[k] for k in ("primary", "secondary", "realtime"))
            where = f"UR simulator {host}"
        else:
            try:
                host, ports = parse_host(robot)
            except LinkError as err:
                log.error("%s", err)
                return 1
            where = f"UR {arm.name} at {host}"

        def make_link() -> Link:
            return UrLink(arm, host, profile=profile, ports=ports)

        def hardware_for(link: Link) -> HardwareComponent:
            assert isinstance(link, UrLink)
            return ur_component(link)

        core = CoreSpec(profile, "ur", host, options={"arm": arm, "ports": ports})
        return run_arm_window(
            profile,
            (serving(live, make_link), hardware_for, UR_CAPABILITIES),
            where,
            quit_after_s,
            config_dir=config_dir,
            key_map=key_map,
            recorder=recorder,
            pad_mapping=pad_mapping,
            control_hz=control_hz,
            live=live,
            cameras=cameras,
            core=core if core_process else None,
        )
    finally:
        recorder.stop()  # after the window's shutdown: the link's closing stopj is in it
        if simulator is not None:
            simulator.stop()


def run_arm_window(
    profile: RobotProfile,
    hardware: tuple[Callable[[], Link], Callable[[Link], HardwareComponent], frozenset[str]],
    where: str,
    quit_after_s: float | None,
    *,
    config_dir: Path,
    key_map: KeyMap,
    pad_mapping: PadMapping | None,
    control_hz: float,
    recorder: Recorder | None = None,
    live: LiveServer | None = None,
    cameras: LocalCameras | None = None,
    core: CoreSpec | None = None,
) -> int:
    """The console's window on an arm (a UR, an xArm): `hardware` is its link factory, its
    component factory and its capabilities (with `core`, the core's process makes its own);
    the window starts the link, zeros are last."""
    from PySide6.QtWidgets import QApplication

    from ocu.core_process import CoreProcessError
    from ocu.gamepad.calibration import CALIBRATION_FILE_NAME, CalibrationStore
    from ocu.windows.main_window import MainWindow

    app = QApplication.instance() or QApplication(sys.argv[:1])
    assert isinstance(app, QApplication)
    make_link, hardware_for, capabilities = hardware
    if cameras is not None and cameras.captures:
        capabilities |= {"cameras"}  # the Video dock, for this machine's cameras
    settings, settings_status = open_settings(config_dir)
    guard = contextlib.ExitStack()
    guard.enter_context(last_zeros_guard())  # the window starts the link
    try:
        window = MainWindow(
            profile,
            make_link,
            where,
            settings,
            key_map,
            settings_status=settings_status,
            recorder=recorder,
            pad_mapping=pad_mapping,
            pad_calibrations=CalibrationStore(config_dir / CALIBRATION_FILE_NAME),
            control_hz=control_hz,
            hardware_for=hardware_for,
            capabilities=capabilities,
            core=core,
        )
    except CoreProcessError as err:  # the core's process did not start or answer
        guard.close()
        log.error("%s", err)
        return 1
    show_live(live, window)
    if cameras is not None:
        cameras.attach(window)
    with guard:
        return run_window(app, window, quit_after_s)


def run_replay(
    profile: RobotProfile,
    path: Path,
    quit_after_s: float | None,
    *,
    config_dir: Path,
    key_map: KeyMap,
    control_hz: float = DEFAULT_CONTROL_HZ,
    live: LiveServer | None = None,
) -> int:
    """The console on a recording: no simulator, no link; plays from the start."""
    from PySide6.QtWidgets import QApplication

    from ocu.hardware.replay import replay_hardware
    from ocu.link.base import LinkError
    from ocu.record.errors import RecordingError
    from ocu.record.ur_replay import open_replay
    from ocu.windows.main_window import MainWindow

    app = QApplication.instance() or QApplication(sys.argv[:1])
    assert isinstance(app, QApplication)
    try:
        source = serve(live, open_replay(path, profile))
    except (RecordingError, LinkError) as err:
        log.error("%s", err)
        return 1
    hardware_for, capabilities = replay_hardware(source)
    settings, settings_status = open_settings(config_dir)
    window = MainWindow(
        source.profile,
        None,
        f"replay {path.name}",
        settings,
        key_map,
        replay=source,
        settings_status=settings_status,
        control_hz=control_hz,
        hardware_for=hardware_for,
        capabilities=capabilities,
    )
    show_live(live, window)
    source.play()
    return run_window(app, window, quit_after_s)


def show_live(live: LiveServer | None, window: MainWindow) -> None:
    """The live server (if any) serves the window's control core; the status bar shows who
    watches and who drives, and a click there revokes the remote drive (docs/live.md)."""
    from ocu.ros.host import live_goal_core

    serve_console(live, window.core, live_goal_core)
    if live is not None:
        from ocu.widgets.live_status import LiveIndicator

        window.link_status.add_indicator(LiveIndicator(live))


def open_settings(config_dir: Path) -> tuple[QSettings, SettingsStatus]:
    """The window layout file in the config directory (created if needed), and whether it may
    be saved: an unreadable one is moved aside first, a read-only folder keeps the layout
    unsaved (ocu.windows.settings_file; the console says so in its Events dock)."""
    from PySide6.QtCore import QSettings

    from ocu.windows.settings_file import ConfigDirError, SettingsStatus, prepare_settings

    path = config_dir / SETTINGS_FILE
    try:
        status = prepare_settings(config_dir)
    except ConfigDirError as err:  # checked at start; changed since
        status = SettingsStatus(path, writable=False, notes=(f"{err}: the layout is not saved",))
    return QSettings(str(path), QSettings.Format.IniFormat), status
