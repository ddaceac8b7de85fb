"""The `ocu-ros` node: ROS 1 commands to the Engineer over the Qt-free link core.

    ocu-ros                                   # the built-in simulator
    ocu-ros _robot:=192.168.0.100             # a robot (the profile's port)
    ocu-ros _robot:=10.0.0.5:10000 _twist_stamped:=true

SIGINT and SIGTERM (and a shutdown asked through ROS) stop the bridge, then shut the link
down, which sends zeros last, then stop the built-in simulator.
"""

from __future__ import annotations

import argparse
import logging
import math
import shlex
import signal
import sys
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from types import FrameType
from typing import Any

from ocu.profile import ProfileError, RobotProfile, load_profile
from ocu.ros.bridge import (
    DEFAULT_CMD_VEL_TIMEOUT_S,
    DEFAULT_RATE_HZ,
    DRIVE_LINEAR,
    DRIVE_TURN,
    BridgeError,
    BridgeSettings,
)
from ocu.ros.environment import master_online, master_uri, missing_ros

log = logging.getLogger("ocu.ros")

NODE_NAME = "ocu_ros"
MASTER_POLL_S = 0.5
STOP_POLL_S = 0.5

PARAMETERS = """\
private parameters (set with _name:=value, a launch file or rosparam):
  ~robot            HOST[:PORT] of the robot; empty: start the built-in simulator
  ~profile          robot profile (TOML); empty: the shipped Engineer profile
  ~sim_args         extra ocu-sim options for the built-in simulator, e.g. "--telemetry-hz 20"
  ~min_linear       m/s; 0 < |linear.x| below it is raised to it (default: profile, 0.2)
  ~min_angular      rad/s; the same for angular.z (default: profile, 0.2)
  ~max_linear       m/s; linear speeds are clamped to it (default: profile default_max)
  ~max_angular      rad/s; the same for angular.z (default: profile default_max)
  ~cmd_vel_timeout  s without cmd_vel before the tracks stop (default 0.5)
  ~twist_stamped    subscribe to geometry_msgs/TwistStamped instead of Twist (default false)
  ~rate             Hz of the control loop: timeout, position control, heartbeat (default 50)
  ~camera           camera to select at start (a name in the profile's link.camera_names)
  ~extension        ask an extended robot for every camera's stream (default false)

topics: cmd_vel, joint_goals in; joint_states, camera/compressed,
camera/<name>/image/compressed, /diagnostics out (see docs/ros.md)
"""


class ConfigError(ValueError):
    """A private parameter of the node has a bad value."""


@dataclass(frozen=True)
class NodeConfig:
    """The node's parameters, checked."""

    robot: tuple[str, int] | None
    profile_path: str | None
    sim_args: tuple[str, ...]
    bridge: BridgeSettings
    max_linear_m_s: float
    max_angular_rad_s: float
    extension: bool
    camera: int | None = None


ParamGetter = Callable[[str, Any], Any]


def _number(get: ParamGetter, name: str, default: float) -> float:
    value = get(name, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f"~{name} must be a finite number, got {value!r}")
    return float(value)


def _flag(get: ParamGetter, name: str, default: bool) -> bool:
    value = get(name, default)
    if not isinstance(value, bool):
        raise ConfigError(f"~{name} must be true or false, got {value!r}")
    return value


def _text(get: ParamGetter, name: str) -> str:
    value = get(name, "")
    if not isinstance(value, str):
        raise ConfigError(f"~{name} must be a string, got {value!r}")
    return value.strip()


def parse_address(text: str, default_port: int) -> tuple[str, int]:
    """HOST[:PORT] into an address (the same syntax as `ocu --robot`)."""
    host, sep, port_text = text.rpartition(":")
    if not sep:
        return text, default_port
    if not host or not port_text.isdigit() or not 1 <= int(port_text) <= 65535:
        raise ConfigError(f"~robot: bad address {text!r}: use HOST[:PORT], PORT in 1-65535")
    return host, int(port_text)


def read_profile(get: ParamGetter) -> tuple[RobotProfile, str | None]:
    """The profile named by ~profile (the shipped one if empty)."""
    path = _text(get, "profile") or None
    try:
        return load_profile(path), path
    except ProfileError as err:
        raise ConfigError(f"~profile: {err}") from err


def read_config(get: ParamGetter, profile: RobotProfile, profile_path: str | None) -> NodeConfig:
    """Every private parameter, checked; `get(name, default)` reads one (rospy.get_param)."""
    robot_text = _text(get, "robot")
    robot = parse_address(robot_text, profile.link.port) if robot_text else None
    try:
        sim_args = tuple(shlex.split(_text(get, "sim_args")))
    except ValueError as err:
        raise ConfigError(f"~sim_args: {err}") from err
    linear, turn = profile.channels[DRIVE_LINEAR], profile.channels[DRIVE_TURN]
    try:
        bridge = BridgeSettings(
            min_linear_m_s=_number(get, "min_linear", linear.min_speed),
            min_angular_rad_s=_number(get, "min_angular", turn.min_speed),
            cmd_vel_timeout_s=_number(get, "cmd_vel_timeout", DEFAULT_CMD_VEL_TIMEOUT_S),
            rate_hz=_number(get, "rate", DEFAULT_RATE_HZ),
            twist_stamped=_flag(get, "twist_stamped", False),
        )
    except BridgeError as err:
        raise ConfigError(str(err)) from err
    camera_text = _text(get, "camera")
    names = profile.link.camera_names
    if camera_text and camera_text not in names:
        raise ConfigError(f"~camera: {camera_text!r} is not one of {list(names)}")
    max_linear = _number(get, "max_linear", linear.default_max)
    max_angular = _number(get, "max_angular", turn.default_max)
    if max_linear < 0.0 or max_angular < 0.0:
        raise ConfigError("~max_linear and ~max_angular must be >= 0")
    return NodeConfig(
        robot=robot,
        profile_path=profile_path,
        sim_args=sim_args,
        bridge=bridge,
        max_linear_m_s=max_linear,
        max_angular_rad_s=max_angular,
        extension=_flag(get, "extension", False),
        camera=names.index(camera_text) if camera_text else None,
    )


class _ToRosout(logging.Handler):
    """Sends ocu's log records through rospy's logger: the console and /rosout."""

    def emit(self, record: logging.LogRecord) -> None:
        logging.getLogger("rosout").handle(record)


def _route_logging_to_ros() -> None:
    ocu_logger = logging.getLogger("ocu")
    ocu_logger.handlers[:] = [_ToRosout()]
    ocu_logger.setLevel(logging.INFO)
    ocu_logger.propagate = False


def build_parser() -> argparse.ArgumentParser:
    """Only --help: the node is configured with ROS private parameters."""
    return argparse.ArgumentParser(
        prog="ocu-ros",
        description="ROS 1 node for the Servosila Engineer: cmd_vel and joint goals in, "
        "joint states, camera images and diagnostics out.",
        epilog=PARAMETERS,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the `ocu-ros` console script."""
    args = list(sys.argv[1:] if argv is None else argv)
    # name:=value arguments are ROS remappings and parameters, for rospy.
    build_parser().parse_args([a for a in args if ":=" not in a])
    # Until rospy is up (waiting for the master), ocu's messages go to stderr.
    ocu_logger = logging.getLogger("ocu")
    ocu_logger.addHandler(logging.StreamHandler())
    ocu_logger.setLevel(logging.INFO)
    reason = missing_ros()
    if reason is not None:
        print(f"ocu-ros: {reason}", file=sys.stderr)
        return 1
    stop = threading.Event()

    def request_stop(signum: int, _frame: FrameType | None) -> None:
        log.info("%s: shutting down", signal.Signals(signum).name)
        stop.set()

    previous = {sig: signal.signal(sig, request_stop) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        return _run(args, stop)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def _wait_for_master(stop: threading.Event) -> bool:
    uri = master_uri()
    told = False
    while not master_online():
        if not told:
            log.info("waiting for the ROS master at %s (start roscore)", uri)
            told = True
        if stop.wait(MASTER_POLL_S):
            return False
    return True


def _run(args: list[str], stop: threading.Event) -> int:
    import rospy

    from ocu.link.core import LinkCore, LinkError, LinkListener
    from ocu.ros.rosbridge import RosBridge, init_node
    from ocu.sim.launcher import SimulatorProcess, SimulatorProcessError

    if not _wait_for_master(stop):
        return 0
    init_node(NODE_NAME, argv=["ocu-ros", *args], keep_logging=False)
    _route_logging_to_ros()
    rospy.on_shutdown(stop.set)

    def private_param(name: str, default: Any) -> Any:
        return rospy.get_param("~" + name, default)

    try:
        profile, profile_path = read_profile(private_param)
        config = read_config(private_param, profile, profile_path)
    except ConfigError as err:
        log.error("bad parameter: %s", err)
        rospy.signal_shutdown("bad parameter")
        return 2

    simulator: SimulatorProcess | None = None
    link: LinkCore | None = None
    bridge: RosBridge | None = None
    try:
        robot = config.robot
        if robot is None:
            try:
                simulator = SimulatorProcess(config.profile_path, list(config.sim_args))
            except SimulatorProcessError as err:
                log.error("%s", err)
                return 1
            robot = simulator.address
            log.info("built-in simulator at %s:%d", *robot)
        try:
            link = LinkCore(profile, robot, extension=config.extension)
        except LinkError as err:
            log.error("%s", err)
            return 1
        for channel, value in (
            (DRIVE_LINEAR, config.max_linear_m_s),
            (DRIVE_TURN, config.max_angular_rad_s),
        ):
            kept = link.set_max_velocity(channel, value)
            if kept != value:
                log.warning(
                    "%s maximum %.3f above the profile's hard maximum: %.3f", channel, value, kept
                )
        if config.camera is not None:
            link.set_command(replace(link.command, camera=config.camera))
        bridge = RosBridge(
            profile, config.bridge, hardware_id=f"{robot[0]}:{robot[1]}", heartbeat=True
        )
        # LinkCore logs its state changes and safety events itself (forwarded to rosout).
        link.listener = bridge.wrap_listener(LinkListener())
        link.start()
        bridge.start(link)
        log.info("commanding %s:%d; SIGINT or SIGTERM stops the robot and exits", *robot)
        while not stop.wait(STOP_POLL_S):
            if bridge.failed.is_set():
                return 1
        return 0
    finally:
        if bridge is not None:
            bridge.stop()
        if link is not None:
            link.shutdown()
            log.info("link shut down, zeros sent last")
        if simulator is not None:
            simulator.stop()
        rospy.signal_shutdown("ocu-ros exiting")


if __name__ == "__main__":
    sys.exit(main())
