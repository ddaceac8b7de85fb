"""Driving with a map through ROS: odom, tf, scan, follow_path and the zones in `ocu-ros`.

The pure parts (messages as data, the model's zones under a ROS command) run without ROS;
the node runs as a child process against a real roscore and the simulator in this process.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import pytest

from ocu.console.model import ConsoleModel
from ocu.nav.geometry import Pose
from ocu.nav.navigator import ZONES_BLIND, ZONES_OFF_NO_DATA, Navigator
from ocu.nav.world import load_world, parse_world
from ocu.profile import RobotProfile
from ocu.protocol.mapping import CommandMapper, scan_frame
from ocu.records import ScanFrame
from ocu.ros.master import RosMaster
from ocu.ros.navigation import (
    FrameTree,
    NavigationError,
    PlanarMount,
    odometry_data,
    path_points,
    quaternion_yaw,
    scan_from_ros,
)
from ocu.sim.rangefinder import RangeSensor, RangeSensorConfig
from ocu.sim.simulator import RobotSimulator
from tests.ros.conftest import ROSPY_WARNINGS, Collector, NodeProcess, needs_ros, wait_for

pytestmark = ROSPY_WARNINGS
LINEAR = "drive_linear"


def test_odometry_as_a_ros_message(profile: RobotProfile) -> None:
    navigator = Navigator(profile, clock=lambda: 10.0, grid=False)
    navigator.reset_odometry(Pose(1.0, 2.0, 0.5))
    data = odometry_data(navigator.estimate())
    assert (data.frame_id, data.child_frame_id) == ("odom", "base_link")
    assert data.position == (1.0, 2.0, 0.0)
    assert quaternion_yaw(*data.orientation_xyzw) == pytest.approx(0.5)
    assert len(data.pose_covariance) == 36
    assert data.pose_covariance[2 * 6 + 2] > 1e3  # z is not estimated


def test_scans_and_paths_from_other_nodes() -> None:
    scan = scan_from_ros(
        angle_min=-1.0,
        angle_increment=0.5,
        range_min=0.1,
        range_max=5.0,
        ranges=[1.0, 0.05, math.inf, 9.0, math.nan],
        received_at=1.0,
        wall_time=2.0,
    )
    ranges = scan.ranges_m
    assert ranges[0] == 1.0
    assert math.isnan(ranges[1])  # below range_min: no measurement
    assert math.isinf(ranges[2])
    assert math.isinf(ranges[3])  # beyond range_max: no return
    assert math.isnan(ranges[4])
    with pytest.raises(NavigationError, match=r"range_min 5\.0 not below range_max 1\.0"):
        scan_from_ros(
            angle_min=0.0,
            angle_increment=1.0,
            range_min=5.0,
            range_max=1.0,
            ranges=[1.0],
            received_at=0.0,
            wall_time=0.0,
        )
    with pytest.raises(NavigationError, match="1000000 beams, at most 4096"):
        scan_from_ros(
            angle_min=0.0,
            angle_increment=1e-6,
            range_min=0.1,
            range_max=5.0,
            ranges=[1.0] * 1_000_000,
            received_at=0.0,
            wall_time=0.0,
        )
    assert path_points("/odom", [(1, 2)]) == [(1.0, 2.0)]
    with pytest.raises(NavigationError, match="the path is in 'map'; give it in 'odom'"):
        path_points("map", [(1, 2)])
    with pytest.raises(NavigationError, match="no poses"):
        path_points("odom", [])


def test_the_model_slows_a_steady_ros_command_as_the_wall_nears(profile: RobotProfile) -> None:
    # ocu-ros's velocities go into the console model (Source.ROS); its zones judge the
    # same steady command again each control step as scans come (was: GuardedSink).
    now = [0.0]
    model = ConsoleModel(profile, clock=lambda: now[0])

    def wall(gap_m: float) -> ScanFrame:
        x = 0.67 + gap_m
        world = parse_world({"wall": [{"from_m": [x, -3.0], "to_m": [x, 3.0]}]})
        packet = RangeSensor(world, RangeSensorConfig(noise_m=0.0)).sweep(Pose(0, 0, 0), 0)
        return scan_frame(packet, now[0], 0.0)

    model.on_scan(wall(2.0))
    model.set_external_velocities({"drive_linear": 0.3, "drive_turn": 0.0, "waist": 0.1})
    model.update(now[0])
    assert model.command().velocities == {"drive_linear": 0.3, "waist": 0.1}
    now[0] += 0.1
    model.on_scan(wall(0.25))
    model.update(now[0])  # the same command, judged again
    assert model.command().velocities == {"drive_linear": pytest.approx(0.2), "waist": 0.1}
    now[0] += 0.1
    model.on_scan(wall(0.02))
    model.update(now[0])
    assert model.command().velocities == {"waist": 0.1}


def wall_scan(gap_m: float, at: float) -> ScanFrame:
    """A noiseless scan of a wall `gap_m` beyond the footprint's front (0.62 m; the
    simulated sensor measures 0.05 m short)."""
    x = 0.67 + gap_m
    world = parse_world({"wall": [{"from_m": [x, -3.0], "to_m": [x, 3.0]}]})
    packet = RangeSensor(world, RangeSensorConfig(noise_m=0.0)).sweep(Pose(0, 0, 0), 0)
    return scan_frame(packet, at, 0.0)


def clear_scan(at: float) -> ScanFrame:
    return scan_from_ros(
        angle_min=-math.pi,
        angle_increment=math.tau / 8,
        range_min=0.1,
        range_max=5.0,
        ranges=[math.inf] * 8,
        received_at=at,
        wall_time=0.0,
    )


def test_the_nearest_obstacle_of_every_fresh_source_counts(profile: RobotProfile) -> None:
    now = [0.0]
    navigator = Navigator(profile, clock=lambda: now[0], grid=False)
    # Two publishers alternate: one sees the wall 2 cm ahead, the other nothing. The latest
    # scan used to win, and every other one let the robot drive into the wall.
    for _ in range(10):
        now[0] += 0.05
        navigator.on_scan(wall_scan(0.02, now[0]), source="/laser in base_link")
        assert navigator.guard(0.3, 0.0).decision.stopped  # type: ignore[union-attr]
        now[0] += 0.05
        navigator.on_scan(clear_scan(now[0]), source="/ghost in base_link")
        state = navigator.guard(0.3, 0.0)
        assert state.decision is not None
        assert state.decision.stopped, state.text
    assert navigator.scan_sources() == ["/ghost in base_link", "/laser in base_link"]
    # Backing away from the wall is never held back.
    backwards = navigator.guard(-0.2, 0.0).decision
    assert backwards is not None
    assert (backwards.linear_m_s, backwards.limited) == (-0.2, False)


def test_a_silent_source_holds_the_drive_to_the_creep_and_fresh_obstacles_still_stop(
    profile: RobotProfile,
) -> None:
    now = [0.0]
    navigator = Navigator(profile, clock=lambda: now[0], grid=False)
    navigator.on_scan(clear_scan(now[0]), source="/front")
    navigator.on_scan(clear_scan(now[0]), source="/rear")
    assert navigator.guard(0.3, 0.0).decision.linear_m_s == 0.3  # type: ignore[union-attr]
    # The rear laser stops; the front one goes on: creep (a source fell silent)...
    for _ in range(8):
        now[0] += 0.1
        navigator.on_scan(clear_scan(now[0]), source="/front")
    state = navigator.guard(0.3, 0.0)
    assert state.blind
    assert state.decision is not None
    assert state.decision.linear_m_s == pytest.approx(0.2)
    assert state.text == f"{ZONES_BLIND}: at most 0.20 m/s (/rear silent)"
    # ...and the front one's wall still stops the robot.
    navigator.on_scan(wall_scan(0.02, now[0]), source="/front")
    state = navigator.guard(0.3, 0.0)
    assert state.decision is not None
    assert state.decision.stopped
    assert state.text.startswith("stopped: obstacle")


def test_staleness_counts_from_arrival_not_from_the_estimated_capture(
    profile: RobotProfile,
) -> None:
    now = [10.0]
    navigator = Navigator(profile, clock=lambda: now[0], grid=False)
    navigator.on_round_trip(0.4)  # a slow link: the scan was taken 0.2 s before it arrived
    navigator.on_scan(clear_scan(now[0]))
    now[0] += 0.45  # the old rule (age from capture, 0.65 s) was blind here
    assert not navigator.guard(0.3, 0.0).blind
    now[0] += 0.06
    assert navigator.guard(0.3, 0.0).blind


def test_frames_place_scans_on_the_chassis() -> None:
    frames = FrameTree()
    assert frames.mount("base_link") == PlanarMount(0.0, 0.0, 0.0)
    assert frames.mount("/base_link") == PlanarMount(0.0, 0.0, 0.0)
    with pytest.raises(NavigationError, match="frame 'laser' is unknown"):
        frames.mount("laser")
    with pytest.raises(NavigationError, match="no frame_id"):
        frames.mount("")
    # A rear laser 0.3 m behind the centre on a 0.1 m high plate, facing backwards.
    frames.set("base_link", "plate", (-0.3, 0.0, 0.1), (0.0, 0.0, 0.0, 1.0))
    half_turn = (0.0, 0.0, 1.0, 0.0)
    frames.set("plate", "rear_laser", (0.0, 0.05, 0.0), half_turn)
    mount = frames.mount("rear_laser")
    assert (mount.x_m, mount.y_m, abs(mount.yaw_rad)) == pytest.approx((-0.3, 0.05, math.pi))
    # Its beam straight ahead (angle 0) points backwards on the chassis.
    scan = mount.place(clear_scan(0.0))
    assert abs(scan.angle_min_rad) == pytest.approx(0.0, abs=1e-12)
    # A frame tilted 90° (a laser looking at the floor) is no planar scan of the floor.
    tilt = math.radians(90.0) / 2.0
    frames.set("base_link", "down", (0.5, 0.0, 0.3), (0.0, math.sin(tilt), 0.0, math.cos(tilt)))
    with pytest.raises(NavigationError, match="tilted 90°"):
        frames.mount("down")
    frames.set("a", "b", (0, 0, 0), (0, 0, 0, 1))
    frames.set("b", "a", (0, 0, 0), (0, 0, 0, 1))
    with pytest.raises(NavigationError, match="loops"):
        frames.mount("a")
    with pytest.raises(NavigationError, match="finite"):
        frames.set("base_link", "x", (math.nan, 0, 0), (0, 0, 0, 1))


def test_a_rear_laser_sees_a_wall_behind(profile: RobotProfile) -> None:
    now = [0.0]
    navigator = Navigator(profile, clock=lambda: now[0], grid=False)
    frames = FrameTree()
    frames.set("base_link", "rear_laser", (0.0, 0.0, 0.2), (0.0, 0.0, 1.0, 0.0))
    mount = frames.mount("rear_laser")
    # The rear laser's own view: the wall 2 cm behind the robot is "ahead" of it.
    seen = wall_scan(0.02 + 0.36 - 0.62, now[0])
    navigator.on_scan(mount.place(seen), source="/rear", mount_xy_m=(mount.x_m, mount.y_m))
    backwards = navigator.guard(-0.2, 0.0).decision
    assert backwards is not None
    assert backwards.stopped
    assert navigator.guard(0.3, 0.0).decision.linear_m_s == 0.3  # type: ignore[union-attr]


def test_paths_far_away_are_refused_not_overflowed(profile: RobotProfile) -> None:
    with pytest.raises(NavigationError, match=r"pose 1 at \(1e\+308, 0\) m is not within"):
        path_points("odom", [(1.0, 0.0), (1e308, 0.0)])
    long_frame = "f" * 1_000_000
    with pytest.raises(NavigationError) as info:
        path_points(long_frame, [(1.0, 0.0)])
    assert len(str(info.value)) < 200


# ---- the node ----------------------------------------------------------------------------


def path_message(points: list[tuple[float, float]], frame: str = "odom") -> Any:
    from geometry_msgs.msg import PoseStamped
    from nav_msgs.msg import Path as PathMessage

    message = PathMessage()
    message.header.frame_id = frame
    for x, y in points:
        pose = PoseStamped()
        pose.header.frame_id = frame
        pose.pose.position.x, pose.pose.position.y = x, y
        pose.pose.orientation.w = 1.0
        message.poses.append(pose)
    return message


@pytest.mark.slow
def test_the_node_publishes_odom_tf_and_scan_and_follows_a_path(
    profile: RobotProfile, ros_master: RosMaster, ros_client: None, tmp_path: Path
) -> None:
    import rospy
    from nav_msgs.msg import Odometry
    from nav_msgs.msg import Path as PathMessage
    from sensor_msgs.msg import LaserScan
    from tf2_msgs.msg import TFMessage

    needs_ros()
    sim = RobotSimulator(
        profile, extended=True, world=load_world("default"), telemetry_hz=10.0, video_fps=0.0
    )
    assert sim.extension is not None
    for camera in range(len(profile.link.camera_names)):
        sim.extension.stop_camera(camera)
    sim.start()
    odom = Collector("odom", Odometry)
    tf = Collector("/tf", TFMessage)
    scan = Collector("scan", LaserScan)
    follow = rospy.Publisher("follow_path", PathMessage, queue_size=1, latch=True)
    process = NodeProcess(tmp_path, sim.address, "_extension:=true")
    try:
        process.wait_connected(follow)
        laser = scan.wait(lambda m: len(m.ranges) == 360, 20.0)
        assert laser.header.frame_id == "base_link"
        ahead = laser.ranges[len(laser.ranges) // 2]  # angle_min is -pi: the middle is ahead
        assert ahead == pytest.approx(4.95, abs=0.05)
        first = odom.wait(lambda m: True, 10.0)
        assert (first.header.frame_id, first.child_frame_id) == ("odom", "base_link")

        # /tf also carries base_link -> tool0 (the arm): look for the odometry's transform.
        def frames(message: Any) -> set[tuple[str, str]]:
            return {(t.header.frame_id, t.child_frame_id) for t in message.transforms}

        tf.wait(lambda m: ("odom", "base_link") in frames(m), 10.0)
        follow.publish(path_message([(1.0, 0.0), (1.5, 0.5)]))
        assert sim.wait_until(lambda s: math.dist(s.pose[:2], (1.5, 0.5)) < 0.2, 30.0), (
            f"the robot is at {sim.state().pose}:\n{process.output()}"
        )
        assert wait_for(lambda: sim.state().all_stopped, 10.0)
        moved = odom.wait(lambda m: m.pose.pose.position.x > 1.3, 5.0, after=odom.count() - 1)
        assert moved.pose.pose.position.y == pytest.approx(sim.state().pose[1], abs=0.1)
    finally:
        follow.unregister()
        for collector in (odom, tf, scan):
            collector.close()
        code = process.stop()
        sim.stop()
    assert code == 0, process.output()
    assert "follow_path: 2 poses in odom, path mode started" in process.output()
    assert "path done" in process.output(), process.output()


@pytest.mark.slow
def test_a_vendor_robot_takes_scan_from_another_node_for_the_zones(
    profile: RobotProfile, ros_master: RosMaster, ros_client: None, tmp_path: Path
) -> None:
    import rospy
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import Twist
    from sensor_msgs.msg import LaserScan

    needs_ros()
    # A wall 0.3 m ahead of the footprint; the vendor robot has no range sensor of its own.
    world = parse_world({"wall": [{"from_m": [0.97, -3.0], "to_m": [0.97, 3.0]}]})
    sim = RobotSimulator(profile, world=world, telemetry_hz=10.0, video_fps=0.0)
    sim.start()
    sensor = RangeSensor(world, RangeSensorConfig(noise_m=0.0))
    scan_pub = rospy.Publisher("scan", LaserScan, queue_size=1)
    cmd_vel = rospy.Publisher("cmd_vel", Twist, queue_size=1)
    diagnostics = Collector("/diagnostics", DiagnosticArray)
    process = NodeProcess(tmp_path, sim.address)

    def zones_text(message: Any) -> str:
        values = {kv.key: kv.value for kv in message.status[1].values}
        return str(values.get("safety zones", ""))

    def publish_scan() -> None:
        # Another node's laser on the robot: what it sees from where the robot truly is.
        packet = sensor.sweep(Pose(*sim.state().pose), 0)
        frame = scan_frame(packet, 0.0, 0.0)
        message = LaserScan()
        message.header.frame_id = "base_link"
        message.header.stamp = rospy.Time.now()
        message.angle_min = frame.angle_min_rad
        message.angle_increment = frame.angle_increment_rad
        message.angle_max = frame.angle_min_rad + frame.angle_increment_rad * 359
        message.range_min, message.range_max = frame.range_min_m, frame.range_max_m
        message.ranges = list(frame.ranges_m)
        scan_pub.publish(message)

    try:
        process.wait_connected(scan_pub)
        process.wait_connected(cmd_vel)
        # Before any scan the zones are off (a vendor robot): say so, then see them take it.
        assert zones_text(diagnostics.wait(lambda m: zones_text(m) != "")) == ZONES_OFF_NO_DATA
        seen = diagnostics.count()
        give_up = time.monotonic() + 20.0
        while not wait_for(
            lambda: any(zones_text(m) != ZONES_OFF_NO_DATA for m in diagnostics.messages[seen:]),
            0.1,
        ):
            assert time.monotonic() < give_up, "the node never took the scans for its zones"
            publish_scan()
        twist = Twist()
        twist.linear.x = 0.45
        started = time.monotonic()
        deadline = started + 6.0
        while time.monotonic() < deadline:
            publish_scan()
            cmd_vel.publish(twist)
            time.sleep(0.1)  # the sensor's and the planner's rate, not a synchronisation
        mapper = CommandMapper(profile)
        speeds = [
            mapper.to_command(r.packet).velocity(LINEAR)
            for r in sim.received_commands()
            if r.time_s > started
        ]
    finally:
        for publisher in (scan_pub, cmd_vel):
            publisher.unregister()
        diagnostics.close()
        code = process.stop()
        sim.stop()
    assert code == 0, process.output()
    assert speeds
    assert max(speeds) <= 0.2 + 1e-3  # capped by the innermost zone at most
    assert sim.state().collisions == 0
