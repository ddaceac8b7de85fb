"""The bridge's decisions for a UR arm, without ROS: no chassis, its arm, its controller's modes."""

from __future__ import annotations

import pytest

from ocu.link.ur_wire import UrRobotStatus
from ocu.profile.ur import load_ur_profile
from ocu.profile.ur_robot import ur_robot_profile
from ocu.protocol.ur import RobotMode, SafetyMode
from ocu.ros.bridge import BridgeCore
from ocu.ros.convert import BridgeError, BridgeSettings
from ocu.ros.diagnostics import DiagnosticLevel, bridge_report, controller_report


class Recorder:
    """A velocity sink that keeps what it was given."""

    def __init__(self) -> None:
        self.sent: list[dict[str, float]] = []

    def set_velocities(self, **velocities: float) -> None:
        self.sent.append(velocities)


@pytest.fixture
def ur_core() -> tuple[BridgeCore, Recorder]:
    core = BridgeCore(ur_robot_profile(load_ur_profile("ur5e")))
    recorder = Recorder()
    core.attach(recorder)
    return core, recorder


def test_a_ur_has_no_drive_and_its_arm_topics_work(ur_core: tuple[BridgeCore, Recorder]) -> None:
    core, _ = ur_core
    assert BridgeSettings.from_profile(core.profile).drive is None
    assert core.arm_available, core.arm_error
    assert core.arm_kinematics is not None
    assert core.arm_kinematics.joints[0] == "shoulder_pan_joint"
    assert core.set_goals(["elbow_joint"], [1.0]) == {"elbow_joint": 1.0}


def test_cmd_vel_for_a_ur_is_refused_sends_nothing_and_is_in_the_diagnostics(
    ur_core: tuple[BridgeCore, Recorder],
) -> None:
    core, recorder = ur_core
    for _ in range(3):
        with pytest.raises(BridgeError, match="no chassis"):
            core.on_cmd_vel(0.3, 0.5)
    assert recorder.sent == []
    core.step()  # no cmd_vel timeout to run, nothing to stop
    assert recorder.sent == []
    values = dict(bridge_report(core.status(), "ur").values)
    assert values["cmd_vel"].startswith("refused")
    assert values["cmd_vel received"] == "3"
    assert values["rejected commands"] == "3"


def _status(
    robot: RobotMode = RobotMode.RUNNING,
    safety: SafetyMode = SafetyMode.NORMAL,
    *,
    estop: bool = False,
    protective: bool = False,
) -> UrRobotStatus:
    return UrRobotStatus(robot, safety, estop, protective)


@pytest.mark.parametrize(
    ("status", "level"),
    [
        (None, DiagnosticLevel.STALE),
        (_status(), DiagnosticLevel.OK),
        (_status(safety=SafetyMode.REDUCED), DiagnosticLevel.WARN),
        (_status(safety=SafetyMode.PROTECTIVE_STOP, protective=True), DiagnosticLevel.ERROR),
        (_status(safety=SafetyMode.ROBOT_EMERGENCY_STOP, estop=True), DiagnosticLevel.ERROR),
        (_status(robot=RobotMode.IDLE), DiagnosticLevel.ERROR),
    ],
)
def test_controller_report_levels(status: UrRobotStatus | None, level: DiagnosticLevel) -> None:
    report = controller_report(status, "10.0.0.7")
    assert report.level is level
    assert report.name == "ocu: robot controller"
    values = dict(report.values)
    if status is not None:
        assert values["robot mode"] == status.robot_mode.name
        assert values["safety mode"] == status.safety_mode.name
        assert report.message == status.describe()
