"""The node's private parameters and its command line, without ROS."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

import ocu
from ocu.profile import RobotProfile
from ocu.ros.node import (
    ConfigError,
    main,
    read_config,
    read_profile,
    read_robot,
)
from ocu.ros.params import CommandLineParams, is_private_arg


def getter(params: dict[str, Any]) -> Any:
    def get(name: str, default: Any) -> Any:
        return params.get(name, default)

    return get


def test_defaults_come_from_the_profile(profile: RobotProfile) -> None:
    config = read_config(getter({}), profile, None)
    assert config.robot is None  # the built-in simulator
    assert config.bridge.min_linear_m_s == profile.channels["drive_linear"].min_speed
    assert config.bridge.min_angular_rad_s == profile.channels["drive_turn"].min_speed
    assert config.bridge.cmd_vel_timeout_s == 0.5
    assert config.bridge.twist_stamped is False
    assert config.max_linear_m_s == profile.channels["drive_linear"].default_max
    assert config.camera is None
    assert config.extension is False


def test_parameters_are_read(profile: RobotProfile) -> None:
    config = read_config(
        getter(
            {
                "robot": "10.0.0.5",
                "min_linear": 0.1,
                "min_angular": 0,  # YAML gives an int
                "cmd_vel_timeout": 1,
                "twist_stamped": True,
                "rate": 20,
                "max_linear": 0.45,
                "camera": "rear",
                "sim_args": "--telemetry-hz 20",
            }
        ),
        profile,
        None,
    )
    assert config.robot == ("10.0.0.5", profile.link.port)
    assert config.bridge.min_linear_m_s == 0.1
    assert config.bridge.min_angular_rad_s == 0.0
    assert config.bridge.cmd_vel_timeout_s == 1.0
    assert read_config(getter({"cmd_vel_timeout": 2}), profile, None).bridge.cmd_vel_timeout_s == 2
    assert config.bridge.twist_stamped is True
    assert config.bridge.rate_hz == 20.0
    assert config.max_linear_m_s == 0.45
    assert config.camera == profile.link.camera_names.index("rear")
    assert config.sim_args == ("--telemetry-hz", "20")
    assert read_config(getter({"robot": "host:1234"}), profile, None).robot == ("host", 1234)


@pytest.mark.parametrize(
    ("params", "match"),
    [
        ({"robot": "host:0"}, "~robot: bad address"),
        ({"robot": "host:http"}, "~robot: bad address"),
        ({"robot": ":10000"}, "~robot: bad address"),
        ({"robot": 5}, "~robot must be a string"),
        ({"min_linear": "fast"}, "~min_linear must be a finite number"),
        ({"min_linear": True}, "~min_linear must be a finite number"),
        ({"min_angular": -0.1}, "min_angular_rad_s"),
        ({"cmd_vel_timeout": 0}, r"~cmd_vel_timeout must be > 0 and at most 2 s, got 0\.0"),
        ({"cmd_vel_timeout": -1.0}, "~cmd_vel_timeout must be > 0"),
        ({"cmd_vel_timeout": 86400}, "~cmd_vel_timeout must be > 0 and at most 2 s, got 86400"),
        ({"cmd_vel_timeout": 2.01}, "at most 2 s"),
        ({"rate": 1000}, "rate_hz"),
        ({"twist_stamped": "yes"}, "~twist_stamped must be true or false"),
        ({"max_angular": -1.0}, "must be >= 0"),
        ({"camera": "belly"}, "~camera: 'belly' is not one of"),
        ({"sim_args": "'unclosed"}, "~sim_args"),
    ],
)
def test_bad_parameters_are_refused(
    profile: RobotProfile, params: dict[str, Any], match: str
) -> None:
    with pytest.raises(ConfigError, match=match):
        read_config(getter(params), profile, None)


def test_profile_parameter(profile: RobotProfile, tmp_path: Any) -> None:
    assert read_profile(getter({}))[1] is None
    with pytest.raises(ConfigError, match="~profile: cannot read profile"):
        read_profile(getter({"profile": str(tmp_path / "missing.toml")}))


def test_a_ur_profile_is_read_as_ocu_reads_it(tmp_path: Any) -> None:
    """A shipped UR name or a UR file (one with `series`): the UR's RobotProfile, no drive."""
    profile, path, arm = read_robot(getter({"profile": "ur5e"}))
    assert arm is not None
    assert arm.name == profile.name
    assert path == "ur5e"
    assert list(profile.channels)[:2] == ["shoulder_pan_joint", "shoulder_lift_joint"]
    config = read_config(getter({"robot": "10.0.0.7:40000"}), profile, path, arm)
    assert config.ur_arm is arm
    assert config.ur_target == "10.0.0.7:40000"
    assert config.robot is None
    assert config.bridge.drive is None
    assert read_config(getter({}), profile, path, arm).ur_target == ""  # the simulator
    with pytest.raises(ConfigError, match="~robot: not HOST:PORT_BASE"):
        read_config(getter({"robot": "host:x"}), profile, path, arm)
    # A UR profile file of the operator's (it has `series`), as `ocu --profile FILE`.
    own = tmp_path / "my_ur.toml"
    own.write_text(
        (Path(ocu.__file__).parent / "profiles/ur/ur5e.toml").read_text(encoding="utf-8"),
        encoding="utf-8",
    )
    _, _, own_arm = read_robot(getter({"profile": str(own)}))
    assert own_arm is not None
    assert own_arm.joint_names == arm.joint_names


@pytest.mark.parametrize("name", ["camera", "sim_args", "max_linear", "twist_stamped", "extension"])
def test_chassis_parameters_are_refused_for_a_ur(name: str) -> None:
    profile, path, arm = read_robot(getter({"profile": "ur10e"}))
    with pytest.raises(ConfigError, match=f"~{name}: not for a UR arm"):
        read_config(getter({name: "x"}), profile, path, arm)


def test_help_lists_the_parameters(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["--help"])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out
    for name in ("~robot", "~min_linear", "~cmd_vel_timeout", "~twist_stamped", "~rate"):
        assert name in out


@pytest.mark.parametrize(
    ("arg", "private"),
    [
        ("_cmd_vel_timeout:=1.0", True),
        ("_robot:=10.0.0.5:10000", True),
        ("_a/b:=1", True),
        ("__name:=ocu", False),  # rospy's special keys
        ("__ns:=/robot1", False),
        ("cmd_vel:=/planner/cmd_vel", False),  # a remapping
        ("_:=1", False),
        ("--help", False),
    ],
)
def test_private_parameter_arguments(arg: str, private: bool) -> None:
    assert is_private_arg(arg) is private


class ParamServer:
    """A parameter server in a dict, with rospy's names and errors (rospy's is tested in
    tests/ros/test_node.py against a real roscore)."""

    def __init__(self, params: dict[str, Any]) -> None:
        self.params = params

    def resolve_name(self, name: str) -> str:
        return name if name.startswith("/") else "/ocu_ros/" + name.removeprefix("~")

    def has_param(self, param_name: str) -> bool:
        return param_name in self.params

    def get_param(self, param_name: str, default: Any = None) -> Any:
        return self.params.get(self.resolve_name(param_name), default)

    def set_param(self, param_name: str, param_value: Any) -> None:
        self.params[param_name] = param_value

    def delete_param(self, param_name: str) -> None:
        del self.params[param_name]


def test_command_line_parameters_are_taken_back() -> None:
    server = ParamServer({"/ocu_ros/rate": 40, "/ocu_ros/min_linear": 0.15, "/other": 1})
    params = CommandLineParams(server)
    params.upload({"cmd_vel_timeout": 1.5, "min_linear": 0.1})
    assert params.get("cmd_vel_timeout", 0.5) == 1.5
    assert params.get("min_linear", 0.2) == 0.1
    del server.params["/ocu_ros/cmd_vel_timeout"]  # deleted by someone else meanwhile
    params.undo()
    assert server.params == {"/ocu_ros/rate": 40, "/ocu_ros/min_linear": 0.15, "/other": 1}
    params.undo()  # idempotent
