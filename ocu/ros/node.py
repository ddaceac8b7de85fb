"""The `ocu-ros` node: ROS 1 commands to the robot through the console's control core.

    ocu-ros                                   # the built-in simulator
    ocu-ros _robot:=192.168.0.100             # a robot (the profile's port)
    ocu-ros _robot:=10.0.0.5:10000 _twist_stamped:=true
    ocu-ros _profile:=ur5e                    # a UR arm: its simulator in this process
    ocu-ros _profile:=ur5e _robot:=10.0.0.7   # a UR controller (ports 30001-30003)

SIGINT and SIGTERM (and a shutdown asked through ROS) stop the bridge, then shut the link
down, which sends zeros last (a UR: stopj), then stop the built-in simulator. So does a
restart of the ROS master, which rospy cannot survive (the new master knows none of the
node's topics): the node then exits with status 3 for a supervisor (roslaunch's respawn) to
start it again.
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import shlex
import signal
import sys
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import FrameType
from typing import Any

from ocu.console.poses import ARM_POSES_NAME, default_config_dir
from ocu.priority import nice_from_env, raise_priority
from ocu.profile import ProfileError, RobotProfile, load_profile
from ocu.profile.ur import UrArmProfile
from ocu.profile.ur_robot import load_ur_arm, ur_robot_profile
from ocu.profile.xarm import XarmProfile, load_xarm_arm
from ocu.profile.xarm_robot import xarm_robot_profile
from ocu.ros.convert import (
    DEFAULT_CMD_VEL_TIMEOUT_S,
    DEFAULT_RATE_HZ,
    MAX_CMD_VEL_TIMEOUT_S,
    BridgeError,
    BridgeSettings,
)
from ocu.ros.environment import (
    master_knows,
    master_online,
    master_pid,
    master_uri,
    missing_ros,
)
from ocu.ros.params import CommandLineParams, is_private_arg, route_logging_to_ros

log = logging.getLogger("ocu.ros")

NODE_NAME = "ocu_ros"
MASTER_POLL_S = 0.5
STOP_POLL_S = 0.5
# The exit status when the ROS master restarted under the node (it must be started again).
EXIT_MASTER_RESTARTED = 3

PARAMETERS = """\
private parameters (set with _name:=value, a launch file or rosparam):
  ~robot            HOST[:PORT] of the robot (a UR: HOST[:PORT_BASE], ports BASE+1..BASE+3);
                    empty: start the built-in simulator (a UR's: in the node's process)
  ~profile          robot profile (TOML), or a UR arm (ur3e, ur5e, ur10e, ur5 or a UR
                    profile file: it has `series`); empty: the shipped Engineer profile
  ~sim_args         extra ocu-sim options for the built-in simulator, e.g. "--telemetry-hz 20"
  ~min_linear       m/s; 0 < |linear.x| below it is raised to it (default: profile, 0.2)
  ~min_angular      rad/s; the same for angular.z (default: profile, 0.2)
  ~max_linear       m/s; linear speeds are clamped to it (default: profile default_max)
  ~max_angular      rad/s; the same for angular.z (default: profile default_max)
  ~cmd_vel_timeout  s without cmd_vel before the tracks stop (default 0.5, at most 2)
  ~twist_stamped    subscribe to geometry_msgs/TwistStamped instead of Twist (default false)
  ~rate             Hz of the bridge's loop and the control thread (default 50)
  ~camera           camera to select at start (a name in the profile's link.camera_names)
  ~extension        ask an extended robot for every camera's stream (default false)
  ~arm_poses        the operator's stored arm poses (TOML); default: the console's
                    arm_poses.toml in $OCU_CONFIG_DIR or ~/.config/ocu
  ~live             [HOST:]PORT: serve the session to Foxglove/Lichtblick (docs/live.md)
  ~live_token       the token its clients give; needed for a non-loopback ~live
                    (default $OCU_LIVE_TOKEN)
  ~live_control     let one live client drive with /cmd_vel (default false)

topics: cmd_vel, joint_goals, arm/pose_goal, arm/twist_cmd, arm/named_pose, follow_path
(nav_msgs/Path in odom), scan (placed by frame_id; /tf, /tf_static) in; joint_states,
camera/compressed, camera/<name>/image/compressed, arm/tool_pose, odom, /tf (odom ->
base_link, base_link -> tool0), scan (when the robot sends ranges), /diagnostics out (see
docs/ros.md and docs/arm.md)

A UR arm has no chassis, cameras or protocol extension: ~sim_args, ~min_linear,
~min_angular, ~max_linear, ~max_angular, ~cmd_vel_timeout, ~twist_stamped, ~camera and
~extension are refused for it (exit status 2), and cmd_vel is refused (/diagnostics says so).

_name:=value arguments hold for this run only: the node puts back (or deletes) what they
replaced on the parameter server when it exits.

exit status: 0 stopped by a signal or ROS, 1 the robot or the simulator could not be used,
2 a bad parameter, 3 the ROS master restarted (restart the node: roslaunch respawn="true")
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
    arm_poses_path: Path | None = None
    #: A UR arm's or an xArm's profile (None: an Engineer); its controller is at `ur_target`
    #: (HOST[:PORT_BASE]; an xArm: its serial device), or its simulator runs in the node
    #: when that is empty.
    ur_arm: UrArmProfile | XarmProfile | None = None
    ur_target: str = ""
    #: ~live and ~live_token (docs/live.md): where to serve the session, who may watch.
    live: tuple[str, int] | None = None
    live_token: str | None = None
    live_control: bool = False


ParamGetter = Callable[[str, Any], Any]


def _number(get: ParamGetter, name: str, default: float) -> float:
    value = get(name, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f"~{name} must be a finite number, got {value!r}")
    return float(value)


def _timeout(get: ParamGetter) -> float:
    value = _number(get, "cmd_vel_timeout", DEFAULT_CMD_VEL_TIMEOUT_S)
    if not 0.0 < value <= MAX_CMD_VEL_TIMEOUT_S:
        raise ConfigError(
            f"~cmd_vel_timeout must be > 0 and at most {MAX_CMD_VEL_TIMEOUT_S:g} s, got {value!r}"
        )
    return value


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


def read_live(get: ParamGetter) -> dict[str, Any]:
    """~live and ~live_token, checked as `ocu --live` checks them."""
    from ocu.live.options import TOKEN_ENV, LiveError, check_exposure, parse_live_address

    text = _text(get, "live")
    control = _flag(get, "live_control", False)
    if not text:
        if control:
            raise ConfigError("~live_control: needs ~live")
        return {}
    try:
        address = parse_live_address(text)
        token = _text(get, "live_token") or os.environ.get(TOKEN_ENV) or None
        check_exposure(address[0], token)
    except (argparse.ArgumentTypeError, LiveError) as err:
        raise ConfigError(f"~live: {err}") from err
    return {"live": address, "live_token": token, "live_control": control}


def parse_address(text: str, default_port: int) -> tuple[str, int]:
    """HOST[:PORT] into an address (the same syntax as `ocu --robot`)."""
    host, sep, port_text = text.rpartition(":")
    if not sep:
        return text, default_port
    if not host or not port_text.isdigit() or not 1 <= int(port_text) <= 65535:
        raise ConfigError(f"~robot: bad address {text!r}: use HOST[:PORT], PORT in 1-65535")
    return host, int(port_text)


def read_robot(
    get: ParamGetter,
) -> tuple[RobotProfile, str | None, UrArmProfile | XarmProfile | None]:
    """The profile named by ~profile (the shipped one if empty), and the UR arm's or the
    xArm's profile when it names one (read as `ocu --profile` reads it)."""
    path = _text(get, "profile") or None
    try:
        arm = load_ur_arm(path)
        if arm is not None:
            return ur_robot_profile(arm), path, arm
        xarm = load_xarm_arm(path)
        if xarm is not None:
            return xarm_robot_profile(xarm), path, xarm
        return load_profile(path), path, None
    except ProfileError as err:
        raise ConfigError(f"~profile: {err}") from err


def read_profile(get: ParamGetter) -> tuple[RobotProfile, str | None]:
    """The profile named by ~profile (the shipped one if empty)."""
    profile, path, _ = read_robot(get)
    return profile, path


#: The parameters of a chassis, its cameras, the protocol extension and the Engineer's
#: simulator process: refused for a UR arm, which has none of them.
NOT_FOR_UR = (
    "sim_args",
    "min_linear",
    "min_angular",
    "max_linear",
    "max_angular",
    "cmd_vel_timeout",
    "twist_stamped",
    "camera",
    "extension",
)
_UNSET = object()


def read_ur_config(
    get: ParamGetter,
    profile: RobotProfile,
    profile_path: str | None,
    arm: UrArmProfile | XarmProfile,
) -> NodeConfig:
    """The parameters for a UR arm, checked; those of a chassis are refused (NOT_FOR_UR)."""
    from ocu.hardware.ur import parse_host
    from ocu.link.base import LinkError

    given = [name for name in NOT_FOR_UR if get(name, _UNSET) is not _UNSET]
    if given:
        raise ConfigError(
            f"{', '.join('~' + n for n in given)}: not for "
            f"{'a UR arm' if isinstance(arm, UrArmProfile) else 'an xArm'} ({arm.name}: no "
            "chassis, cameras or protocol extension; its simulator runs in the node)"
        )
    target = _text(get, "robot")
    if target and isinstance(arm, UrArmProfile):
        try:
            parse_host(target)
        except LinkError as err:
            raise ConfigError(f"~robot: {err}") from err
    try:
        bridge = BridgeSettings.from_profile(profile, rate_hz=_number(get, "rate", DEFAULT_RATE_HZ))
    except BridgeError as err:
        raise ConfigError(str(err)) from err
    return NodeConfig(
        robot=None,
        profile_path=profile_path,
        sim_args=(),
        bridge=bridge,
        max_linear_m_s=0.0,
        max_angular_rad_s=0.0,
        extension=False,
        arm_poses_path=Path(_text(get, "arm_poses") or default_config_dir() / ARM_POSES_NAME),
        ur_arm=arm,
        ur_target=target,
        **read_live(get),
    )


def read_config(
    get: ParamGetter,
    profile: RobotProfile,
    profile_path: str | None,
    ur_arm: UrArmProfile | XarmProfile | None = None,
) -> NodeConfig:
    """Every private parameter, checked; `get(name, default)` reads one (rospy.get_param)."""
    if ur_arm is not None:
        return read_ur_config(get, profile, profile_path, ur_arm)
    robot_text = _text(get, "robot")
    robot = parse_address(robot_text, profile.link.port) if robot_text else None
    try:
        sim_args = tuple(shlex.split(_text(get, "sim_args")))
    except ValueError as err:
        raise ConfigError(f"~sim_args: {err}") from err
    try:
        defaults = BridgeSettings.from_profile(profile)
        linear, turn = (profile.channels[name] for name in defaults.drive_channels())
        bridge = BridgeSettings.from_profile(
            profile,
            min_linear_m_s=_number(get, "min_linear", linear.min_speed),
            min_angular_rad_s=_number(get, "min_angular", turn.min_speed),
            cmd_vel_timeout_s=_timeout(get),
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
        arm_poses_path=Path(_text(get, "arm_poses") or default_config_dir() / ARM_POSES_NAME),
        **read_live(get),
    )


def build_parser() -> argparse.ArgumentParser:
    """Only --help: the node is configured with ROS private parameters."""
    return argparse.ArgumentParser(
        prog="ocu-ros",
        description="ROS 1 node for the Servosila Engineer or a Universal Robots arm: cmd_vel, "
        "joint goals and arm commands in, joint states, camera images and diagnostics out.",
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
    try:
        nice = nice_from_env()
    except ValueError as err:
        print(f"ocu-ros: {err}", file=sys.stderr)
        return 2
    # First, before rospy and the link start a thread: threads inherit it (ocu.priority).
    ocu_logger.info("scheduling priority: %s", raise_priority(nice).text)
    stop = SignalStop()

    def request_stop(signum: int, _frame: FrameType | None) -> None:
        # Nothing that takes a lock here: the handler runs between two bytecodes of the main
        # thread, which may hold rospy's XML-RPC lock, and logging goes to /rosout through
        # it (a deadlock seen when SIGTERM came while the bridge was subscribing).
        stop.signal_name = signal.Signals(signum).name
        stop.set()

    previous = {sig: signal.signal(sig, request_stop) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        return _run(args, stop)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


class SignalStop(threading.Event):
    """Set by SIGINT/SIGTERM; remembers which, for the log line written outside the handler."""

    signal_name = ""

    def log_reason(self) -> None:
        if self.signal_name:
            log.info("%s: shutting down", self.signal_name)


class MasterWatch:
    """Notices that the ROS master restarted: another master process answers at its URI, or
    the master answers without this node.

    rospy registers a node's topics once, at start; a new master knows none of them, so no
    new publisher can reach the node (its existing connections go on). The node cannot
    register again, so it says so and exits for a supervisor to restart it.
    """

    def __init__(self) -> None:
        import rospy

        self.name = rospy.get_name()
        self.uri = rospy.get_node_uri() or ""
        self._pid = master_pid()
        self._registered = False
        self._silent = False

    def restarted(self) -> bool:
        """Poll the master (two calls of at most 1 s); True once it restarted."""
        pid = master_pid()
        known = master_knows(self.name, self.uri) if pid is not None else None
        if pid is None or known is None:
            if not self._silent:
                self._silent = True
                log.warning(
                    "the ROS master at %s does not answer: connected topics go on, new "
                    "publishers cannot find this node until it is back",
                    master_uri(),
                )
            return False
        if self._silent:
            self._silent = False
            log.info("the ROS master answers again")
        if self._pid is None:
            self._pid = pid
        if known:
            self._registered = True
        # Unknown right after start: rospy registers from a thread of its own, a moment later.
        if pid == self._pid and (known or not self._registered):
            return False
        log.error(
            "the ROS master at %s restarted (pid %d, was %d) and no longer knows %s: new "
            "publishers cannot reach it and rospy cannot register again; stopping the robot "
            "and exiting with status %d for a supervisor to restart the node (roslaunch: "
            'respawn="true")',
            master_uri(),
            pid,
            self._pid,
            self.name,
            EXIT_MASTER_RESTARTED,
        )
        return True


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

    from ocu.ros.topics import init_node

    if not _wait_for_master(stop):
        return 0
    # rospy would upload the _name:=value arguments itself and leave them on the parameter
    # server after the run; CommandLineParams uploads them and takes them back at exit.
    init_node(
        NODE_NAME,
        argv=["ocu-ros", *(a for a in args if not is_private_arg(a))],
        keep_logging=False,
    )
    route_logging_to_ros()
    rospy.on_shutdown(stop.set)
    params = CommandLineParams(rospy)
    try:
        try:
            try:
                values = rospy.client.load_command_line_node_params(args)
            except rospy.ROSInitException as err:
                raise ConfigError(str(err)) from err
            params.upload(values)
            profile, profile_path, ur_arm = read_robot(params.get)
            config = read_config(params.get, profile, profile_path, ur_arm)
        except ConfigError as err:
            log.error("bad parameter: %s", err)
            return 2
        return _command_robot(profile, config, stop)
    finally:
        params.undo()
        rospy.signal_shutdown("ocu-ros exiting")


def _name_os_threads() -> None:
    """Give the node's own threads ("ocu-control", "ocu-ros-bridge" ...) their names in the
    OS as well: top -H, ps -L and /proc/PID/task/*/comm show them (15 characters at most)."""
    for thread in threading.enumerate():
        if not thread.name.startswith("ocu-") or thread.native_id is None:
            continue
        try:
            Path(f"/proc/self/task/{thread.native_id}/comm").write_text(thread.name[:15])
        except OSError:
            continue  # gone meanwhile, not Linux, no /proc: the names are a convenience


def _command_robot(profile: RobotProfile, config: NodeConfig, stop: threading.Event) -> int:
    from ocu.console.model import ConsoleModel
    from ocu.core.hardware import HardwareError
    from ocu.hardware.registry import HARDWARE
    from ocu.hardware.ur import SIM_HOST, SimulatedUr
    from ocu.headless import HeadlessConsole
    from ocu.link.base import LinkError
    from ocu.live.options import LiveError, serve, serve_console, start_live
    from ocu.ros.host import ModelSink, end_path, follow_path, live_goal_core
    from ocu.ros.rosbridge import RosBridge
    from ocu.sim.launcher import SimulatorProcess, SimulatorProcessError

    simulator: SimulatorProcess | None = None
    kind = ""
    console: HeadlessConsole | None = None
    sink: ModelSink | None = None
    bridge: RosBridge | None = None
    try:
        robot = config.robot
        if config.ur_arm is not None:
            # A UR arm: its controller over TCP, or its simulator in this process (free
            # ports on 127.0.0.1), which the hardware's shutdown stops after the last stopj.
            kind = "ur" if isinstance(config.ur_arm, UrArmProfile) else "xarm"
            plugin = kind if config.ur_target else f"{kind}-sim"
            try:
                hardware = HARDWARE.create(plugin, profile, config.ur_target, arm=config.ur_arm)
            except (LinkError, HardwareError, OSError) as err:
                log.error("%s", err)
                return 1
            if isinstance(hardware, SimulatedUr):
                ports = hardware.simulator.ports
                where = f"the UR simulator ({config.ur_arm.name}) at {SIM_HOST}:" + ",".join(
                    str(ports[k]) for k in ("primary", "secondary", "realtime")
                )
                log.info("built-in %s", where)
            elif kind == "xarm":
                where = f"xArm {config.ur_arm.name} on {config.ur_target or 'its simulator'}"
            else:
                where = f"UR {config.ur_arm.name} at {config.ur_target}"
            hardware_id = config.ur_target or (f"ur-sim {SIM_HOST}" if kind == "ur" else plugin)
        else:
            if robot is None:
                try:
                    simulator = SimulatorProcess(config.profile_path, list(config.sim_args))
                except SimulatorProcessError as err:
                    log.error("%s", err)
                    return 1
                robot = simulator.address
                log.info("built-in simulator at %s:%d", *robot)
            hardware_id = where = f"{robot[0]}:{robot[1]}"
            try:
                hardware = HARDWARE.create(
                    "engineer", profile, hardware_id, extension=config.extension
                )
            except (LinkError, HardwareError) as err:
                log.error("%s", err)
                return 1
        try:
            live = start_live(profile, config.live, config.live_token, config.live_control)
        except LiveError as err:
            log.error("%s", err)
            return 1
        # The console's control core (ocu.core): the model's mux, limits, zones and path
        # mode, its control thread at ~rate (the console's 50 Hz by default), which also
        # beats the link's heartbeat.
        model = ConsoleModel(profile, arm_poses_path=config.arm_poses_path)
        model.nav.grid = None  # no map view: no occupancy grid to build from each scan
        serve(live, hardware.link)
        model.events.message.connect(lambda text: log.info("%s", text), direct=True)
        model.events.position_message.connect(lambda text: log.info("%s", text), direct=True)
        # The node is the only commander: the maxima ROS is held to are the model's.
        drive = config.bridge.drive
        for channel, value in (
            ((drive[0], config.max_linear_m_s), (drive[1], config.max_angular_rad_s))
            if drive is not None
            else ()
        ):
            kept = model.set_max_velocity(channel, value)
            if kept != value:
                log.warning(
                    "%s maximum %.3f above the profile's hard maximum: %.3f", channel, value, kept
                )
        if config.camera is not None:
            model.select_camera(config.camera)  # before anything is sent
        headless = console = HeadlessConsole(
            model, hardware, control_period_s=1.0 / config.bridge.rate_hz
        )
        serve_console(live, console.manager, live_goal_core)
        # The model feeds its own navigator (odometry, the zones, the path mode); the bridge
        # publishes from it, hands it other nodes' scans and /follow_path.
        sink = ModelSink(console, silent_after_s=profile.link.gui_alive_timeout_s)
        # Odometry, scans and /follow_path are a chassis's: none for a robot without one.
        chassis = drive is not None
        ros = bridge = RosBridge(
            profile,
            config.bridge,
            hardware_id=hardware_id,
            arm_poses_path=config.arm_poses_path,
            navigator=model.nav if chassis else None,
            feed_navigator=False,
            on_path=(lambda points: follow_path(headless, ros.core, points)) if chassis else None,
            on_cmd_vel=lambda: end_path(headless),
            on_step=sink.stepped,
        )
        sink.start(bridge.core)
        # The link logs its state changes and safety events itself (forwarded to rosout);
        # the bridge subscribes to them: LINK LOST stops what ROS moves.
        bridge.start(hardware.link, model.limits, sink=sink)
        console.start()
        _name_os_threads()
        log.info("commanding %s; SIGINT or SIGTERM stops the robot and exits", where)
        master = MasterWatch()
        while not stop.wait(STOP_POLL_S):
            if bridge.failed.is_set():
                return 1
            if console.manager.error is not None:
                return 1  # the control thread died (logged); the link zeroed without it
            if master.restarted():
                return EXIT_MASTER_RESTARTED
        if isinstance(stop, SignalStop):
            stop.log_reason()
        return 0
    finally:
        if bridge is not None:
            bridge.stop()
        if sink is not None:
            sink.close()
        if console is not None:
            console.stop()
            last = (
                "zeros" if config.ur_arm is None else "the stop move" if kind == "xarm" else "stopj"
            )
            log.info("link shut down, %s sent last", last)
        if simulator is not None:
            simulator.stop()


if __name__ == "__main__":
    sys.exit(main())
