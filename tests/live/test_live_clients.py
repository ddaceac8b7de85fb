"""The live server with a client that is not ours: the npm Foxglove client run by Node.js.

The data comes from the simulator (in this process) through a real UdpLink on 127.0.0.1; the
client decodes the CDR with Foxglove's own decoder, and what it decoded is checked against
what the link decoded from the simulator's datagrams.
"""

from __future__ import annotations

import hashlib
import math
import re
import threading
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import pytest

from ocu.link.live import UdpLink
from ocu.live.navigation import FOOTPRINT, MAP, ODOM, PLAN
from ocu.live.robot import (
    DIAGNOSTICS,
    ROBOT_DESCRIPTION,
    SCAN,
    SCAN_FRAME,
    TF,
    TF_STATIC,
    RobotFrames,
)
from ocu.live.server import LiveServer
from ocu.model.tree import axis_rotation
from ocu.model.urdf import profile_urdf_path
from ocu.nav.navigator import Navigator
from ocu.nav.world import load_world
from ocu.profile import RobotProfile
from ocu.record import schemas as s
from ocu.records import CommandSent, LinkEvent, LinkState, ScanFrame, TelemetryFrame, VideoFrame
from ocu.sim.simulator import RobotSimulator
from tests.live.node_client import DEADLINE_S, NodeClient, count, require_node


class Seen:
    """What the link decoded, keyed by the stamp the server gives it."""

    def __init__(self, server: LiveServer) -> None:
        self.server = server
        self.lock = threading.Lock()
        self.telemetry: dict[int, TelemetryFrame] = {}
        self.video: dict[int, VideoFrame] = {}
        self.scans: dict[int, ScanFrame] = {}

    def __call__(self, event: LinkEvent) -> None:
        with self.lock:
            if isinstance(event, TelemetryFrame):
                self.telemetry[self.server.wall_ns(event.received_at)] = event
            elif isinstance(event, VideoFrame):
                self.video[self.server.wall_ns(event.received_at)] = event
            elif isinstance(event, ScanFrame):
                self.scans[self.server.wall_ns(event.received_at)] = event


@dataclass
class Session:
    server: LiveServer
    link: UdpLink
    sim: RobotSimulator
    seen: Seen

    @property
    def url(self) -> str:
        return f"ws://127.0.0.1:{self.server.address[1]}"


@pytest.fixture
def session(profile: RobotProfile) -> Iterator[Session]:
    require_node()
    sim = RobotSimulator(
        profile, telemetry_hz=50.0, video_fps=15.0, video_size=(160, 120), extended=True
    )
    sim.start()
    server = LiveServer(profile, "127.0.0.1", 0)
    server.start()
    link = UdpLink(profile, sim.address, gui_alive_timeout_s=None, extension=True)
    seen = Seen(server)
    link.subscribe(seen)
    server.attach(link)
    link.start()
    link.set_velocities(waist=0.3)
    try:
        yield Session(server, link, sim, seen)
    finally:
        link.shutdown()
        server.stop()
        sim.stop()


def stamp_ns(stamp: dict[str, int]) -> int:
    return int(stamp["sec"]) * 1_000_000_000 + int(stamp["nanosec"])


def test_a_foxglove_client_decodes_the_robot_as_the_simulator_sent_it(
    session: Session, profile: RobotProfile
) -> None:
    front = s.camera_topic(profile.link.camera_names[0])
    topics = [s.JOINT_STATES, TF, TF_STATIC, ROBOT_DESCRIPTION, front, SCAN, s.LINK_STATS]
    topics.append(DIAGNOSTICS)
    client = NodeClient(session.url, topics=topics)
    try:
        assert client.wait(count(s.JOINT_STATES, 20)), client.events[-5:]
        assert client.wait(count(TF, 5))
        assert client.wait(count(front, 2))
        assert client.wait(count(s.LINK_STATS, 1))
        assert client.wait(count(SCAN, 1))
        assert client.wait(count(ROBOT_DESCRIPTION, 1))
        assert client.wait(count(DIAGNOSTICS, 2))
    finally:
        client.close()
    assert not client.of("error")
    info = client.of("serverInfo")[0]
    assert info["protocol"] == "foxglove.websocket.v1"
    advertised = {
        topic: (schema, encoding) for topic, schema, encoding in client.of("advertise")[0]["topics"]
    }
    assert advertised[s.JOINT_STATES] == ("sensor_msgs/msg/JointState", "cdr")
    assert advertised[front] == ("sensor_msgs/msg/CompressedImage", "cdr")
    every = [e for e in client.events if e["event"] == "message"]
    assert all(e["trailing"] is False for e in every)  # each payload read to its last byte

    # /joint_states: the very readings the link decoded from the simulator's datagrams.
    with session.seen.lock:
        telemetry = dict(session.seen.telemetry)
        video = dict(session.seen.video)
        scans = dict(session.seen.scans)
    states = client.messages(s.JOINT_STATES)
    moved = set()
    for message in states:
        decoded = message["decoded"]
        stamp = stamp_ns(decoded["header"]["stamp"])
        assert message["receive_ns"] == stamp
        frame = telemetry[stamp]
        expected = {n: r for n, r in frame.readings.items() if r.angle_rad is not None}
        assert decoded["name"] == list(expected)
        assert decoded["position"] == [r.angle_rad for r in expected.values()]
        assert decoded["effort"] == [r.current_a for r in expected.values()]
        moved.add(round(decoded["position"][decoded["name"].index("waist")], 6))
    assert len(moved) > 5  # the waist turned while the client watched

    # /tf: the waist's transform is its URDF origin turned by the angle the link decoded.
    frames = RobotFrames.load(profile)
    assert frames is not None
    waist = frames.tree.joint("waist")
    for message in client.messages(TF)[-3:]:
        stamp = stamp_ns(message["decoded"]["transforms"][0]["header"]["stamp"])
        angle = telemetry[stamp].readings["waist"].angle_rad
        assert angle is not None
        [moving] = [
            t for t in message["decoded"]["transforms"] if t["child_frame_id"] == waist.child
        ]
        expected_matrix = waist.origin @ axis_rotation(waist.unit_axis, angle)
        q = moving["transform"]["rotation"]
        rotation = quaternion_matrix(q["x"], q["y"], q["z"], q["w"])
        np.testing.assert_allclose(rotation, expected_matrix[:3, :3], atol=1e-9)
        assert moving["header"]["frame_id"] == waist.parent

    static = client.messages(TF_STATIC)[0]["decoded"]["transforms"]
    fixed = {j.child for j in frames.tree.joints.values() if j.type == "fixed"}
    assert {t["child_frame_id"] for t in static} == fixed | {SCAN_FRAME}
    description = client.messages(ROBOT_DESCRIPTION)[0]["decoded"]["data"]
    assert description == frames.urdf_text  # the file, meshes named for the client (below)

    image = client.messages(front)[-1]
    decoded_image = image["decoded"]
    jpeg = video[stamp_ns(decoded_image["header"]["stamp"])].jpeg
    assert decoded_image["format"] == "jpeg"
    assert decoded_image["data"] == {"bytes": len(jpeg), "head": list(jpeg[:4])}

    # /diagnostics: the link's report, as ocu-ros publishes it.
    [status] = client.messages(DIAGNOSTICS)[-1]["decoded"]["status"]
    assert status["name"] == "ocu: robot link"
    # Connected before the client came; a warning while the loss estimate settles.
    assert status["message"].startswith("connected")
    assert status["level"] in (0, 1)
    values = {v["key"]: v["value"] for v in status["values"]}
    assert values["state"] == LinkState.CONNECTED.label
    assert int(values["telemetry packets"]) > 0

    scan = client.messages(SCAN)[-1]["decoded"]
    sent = scans[stamp_ns(scan["header"]["stamp"])]
    assert scan["header"]["frame_id"] == SCAN_FRAME
    assert len(scan["ranges"]) == len(sent.ranges_m)
    assert math.isclose(scan["angle_increment"], sent.angle_increment_rad, rel_tol=1e-6)


def quaternion_matrix(x: float, y: float, z: float, w: float) -> np.ndarray:
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def test_many_clients_each_get_every_message_of_their_topics(session: Session) -> None:
    clients = [
        NodeClient(
            session.url, topics=[s.JOINT_STATES] if i % 2 else [s.JOINT_STATES, TF], brief=True
        )
        for i in range(8)
    ]
    try:
        for client in clients:
            assert client.wait(count(s.JOINT_STATES, 50)), client.events[-3:]
    finally:
        for client in clients:
            client.close()
    for i, client in enumerate(clients):
        stamps = [m["receive_ns"] for m in client.messages(s.JOINT_STATES)]
        assert stamps == sorted(stamps)
        assert not client.of("error")
        assert bool(client.messages(TF)) == (i % 2 == 0)
    # Every client saw the same consecutive run of telemetry: none skipped one in between.
    with session.seen.lock:
        all_stamps = sorted(session.seen.telemetry)
    for client in clients:
        stamps = [m["receive_ns"] for m in client.messages(s.JOINT_STATES)]
        first = all_stamps.index(stamps[0])
        assert stamps == all_stamps[first : first + len(stamps)]


def test_a_client_sending_garbage_is_closed_and_harms_nobody(session: Session) -> None:
    good = NodeClient(session.url, topics=[s.JOINT_STATES], brief=True)
    try:
        assert good.wait(count(s.JOINT_STATES, 5))
        bad = NodeClient(session.url, topics=[], garbage=50)
        try:
            assert bad.wait(lambda events: any(e["event"] == "close" for e in events))
        finally:
            bad.close()
        [closed] = bad.of("close")
        assert closed["code"] == 1008
        assert bad.of("status")  # it was told why, frame by frame, until closed
        before = len(good.messages(s.JOINT_STATES))
        assert good.wait(count(s.JOINT_STATES, before + 25))
        assert not good.of("close")
    finally:
        good.close()
    stats = session.server.stats()
    assert stats.closed_for_refused == 1


def test_a_slow_client_drops_frames_within_its_bound_and_delays_nobody(
    profile: RobotProfile,
) -> None:
    require_node()
    buffer_bytes = 256 * 1024
    sim = RobotSimulator(profile, telemetry_hz=50.0, video_fps=30.0, video_size=(320, 240))
    sim.start()
    server = LiveServer(profile, "127.0.0.1", 0, client_buffer_bytes=buffer_bytes)
    server.start()
    link = UdpLink(profile, sim.address, gui_alive_timeout_s=None)
    server.attach(link)
    link.start()
    front = s.camera_topic(profile.link.camera_names[0])
    slow = NodeClient(
        f"ws://127.0.0.1:{server.address[1]}",
        topics=[front, s.JOINT_STATES],
        paused=True,
        brief=True,
    )
    try:
        assert slow.wait(lambda events: any(e["event"] == "paused" for e in events))
        assert poll(lambda: any(c.dropped > 50 for c in server.stats().clients))
        fast = NodeClient(
            f"ws://127.0.0.1:{server.address[1]}", topics=[front, s.JOINT_STATES], brief=True
        )
        try:
            assert fast.wait(count(s.JOINT_STATES, 100))
        finally:
            fast.close()
        stats = server.stats()
    finally:
        slow.close()
        link.shutdown()
        server.stop()
        sim.stop()
    [slow_stats] = [c for c in stats.clients if c.dropped > 0]
    # The bound: what waits for a client never exceeds its buffer.
    assert slow_stats.peak_queued_bytes <= buffer_bytes
    latencies = [m["local_ms"] - m["receive_ns"] / 1e6 for m in fast.messages(s.JOINT_STATES)]
    latencies.sort()
    assert latencies[len(latencies) // 2] < 50.0, latencies[-5:]  # ms from the link's arrival


def poll(predicate: object, timeout_s: float = DEADLINE_S) -> bool:
    import time

    assert callable(predicate)
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        threading.Event().wait(0.02)
    return bool(predicate())


def test_odometry_and_the_map_reach_the_client(profile: RobotProfile) -> None:
    require_node()
    sim = RobotSimulator(
        profile, telemetry_hz=50.0, video_fps=0.0, extended=True, world=load_world("default")
    )
    sim.start()
    server = LiveServer(profile, "127.0.0.1", 0)
    server.start()
    navigator = Navigator(profile)
    server.serve_navigation(navigator)
    link = UdpLink(profile, sim.address, gui_alive_timeout_s=None, extension=True)

    def feed(event: LinkEvent) -> None:  # as the console model feeds its navigator
        if isinstance(event, TelemetryFrame):
            navigator.on_telemetry(event)
        elif isinstance(event, CommandSent):
            navigator.on_command(event.command, event.sent_at)
        elif isinstance(event, ScanFrame):
            navigator.on_scan(event)

    link.subscribe(feed)
    server.attach(link)
    link.start()
    topics = [ODOM, MAP, TF, PLAN, FOOTPRINT]
    client = NodeClient(f"ws://127.0.0.1:{server.address[1]}", topics=topics)
    try:
        assert client.wait(count(PLAN, 1))
        assert client.messages(PLAN)[0]["decoded"]["poses"] == []  # no assisted mode yet
        navigator.start_path([(1.0, 0.0), (1.0, 1.0)])  # the path the path mode would drive
        link.set_velocities(drive_turn=0.4)
        assert client.wait(count(MAP, 3)), client.events[-3:]
        assert client.wait(count(ODOM, 20))
        assert client.wait(lambda events: any(m["decoded"]["poses"] for m in client.messages(PLAN)))
    finally:
        client.close()
        link.shutdown()
        server.stop()
        sim.stop()
    assert not client.of("error")
    every = [e for e in client.events if e["event"] == "message"]
    assert all(m["trailing"] is False for m in every)
    plan = next(m["decoded"] for m in client.messages(PLAN) if m["decoded"]["poses"])
    assert plan["header"]["frame_id"] == "odom"
    ends = [(p["pose"]["position"]["x"], p["pose"]["position"]["y"]) for p in plan["poses"]]
    assert ends[-1] == pytest.approx((1.0, 1.0), abs=1e-6)
    footprint = client.messages(FOOTPRINT)[0]["decoded"]
    assert footprint["header"]["frame_id"] == "base_link"
    corners = [c for p in footprint["polygon"]["points"] for c in (p["x"], p["y"])]
    outline = profile.navigation.footprint
    assert outline is not None
    assert corners == pytest.approx([c for xy in outline.corners_m for c in xy], abs=1e-6)
    odometry = [m["decoded"] for m in client.messages(ODOM)]
    assert {o["header"]["frame_id"] for o in odometry} == {"odom"}
    assert {o["child_frame_id"] for o in odometry} == {"base_link"}
    headings = {round(o["pose"]["pose"]["orientation"]["z"], 4) for o in odometry}
    assert len(headings) > 3  # the robot turned while the client watched
    on_tf = [
        t
        for m in client.messages(TF)
        for t in m["decoded"]["transforms"]
        if t["child_frame_id"] == "base_link"
    ]
    assert on_tf
    assert on_tf[0]["header"]["frame_id"] == "odom"
    grid = navigator.grid
    assert grid is not None
    last = client.messages(MAP)[-1]
    info = last["decoded"]["info"]
    assert (info["width"], info["height"]) == (grid.cells, grid.cells)
    assert math.isclose(info["resolution"], grid.resolution_m, rel_tol=1e-6)
    cells = last["decoded"]["data"]
    assert len(cells) == grid.cells * grid.cells
    assert set(cells) <= {-1, *range(101)}
    assert max(cells) > 50  # the walls the scans saw
    assert cells.count(-1) > len(cells) // 2  # most of the map unseen


def test_the_robots_meshes_are_fetched_and_nothing_else(profile: RobotProfile) -> None:
    require_node()
    urdf = profile_urdf_path(profile)
    server = LiveServer(profile, "127.0.0.1", 0)
    server.start()
    probes = [
        "package://ocu_robot/../engineer.urdf",
        "package://ocu_robot/meshes/../../pyproject.toml",
        f"file://{urdf}",
        str(urdf),
        "package://ocu_robot/meshes/not_there.stl",
    ]
    client = NodeClient(
        f"ws://127.0.0.1:{server.address[1]}",
        topics=[ROBOT_DESCRIPTION],
        fetchMeshes=True,
        fetch=probes,
    )
    try:
        assert client.wait(count(ROBOT_DESCRIPTION, 1))
        description = client.messages(ROBOT_DESCRIPTION)[0]["decoded"]["data"]
        names = re.findall(r'<mesh[^>]*filename="([^"]*)"', description)
        assert names
        assert client.wait(lambda events: len(client.of("asset")) >= len(set(names)) + 5)
        assert not client.of("close")  # five probes: told no, still connected
    finally:
        client.close()
        server.stop()
    assert client.of("serverInfo")[0]["capabilities"] == ["assets"]
    on_disk = re.findall(r'<mesh[^>]*filename="([^"]*)"', urdf.read_text())
    # The served URDF is the file with its mesh paths renamed for the client, nothing else.
    assert [n.removeprefix("package://ocu_robot/") for n in names] == on_disk
    assert re.sub(r'filename="[^"]*"', "", description) == re.sub(
        r'filename="[^"]*"', "", urdf.read_text()
    )
    answers = {a["uri"]: a for a in client.of("asset")}
    for name, relative in zip(names, on_disk, strict=True):
        data = (urdf.parent / relative).read_bytes()
        assert answers[name]["status"] == 0
        assert answers[name]["sha256"] == hashlib.sha256(data).hexdigest()
    for probe in probes:
        assert answers[probe]["status"] == 1
        assert "not a mesh of this robot" in answers[probe]["error"]
