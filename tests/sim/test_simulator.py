"""The simulator over real UDP sockets on 127.0.0.1: physics, link behaviour and faults."""

from __future__ import annotations

import io
import math
import select
import socket
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any, TypeVar

import pytest
from PIL import Image, ImageChops

from ocu.net.transport import VIRTUAL_OCU, VIRTUAL_ROBOT, VirtualWire
from ocu.profile import RobotProfile, load_profile
from ocu.protocol import Codec, MotorRecord, Packet, TelemetryPacket, VideoFramePacket
from ocu.protocol.mapping import CommandMapper, read_telemetry
from ocu.protocol.wire import make_codec
from ocu.records import Command
from ocu.sim import FaultConfig, RobotSimulator, SimState
from ocu.sim.robot import (
    DEVICE_STATE_OPERATIONAL,
    OPERATION_MODE_VELOCITY,
    STATUS_AT_LOWER_LIMIT,
    STATUS_AT_UPPER_LIMIT,
    STATUS_SUPPRESSED,
    STATUS_WATCHDOG_STOP,
)
from ocu.sim.video import (
    DEFAULT_QUALITY,
    MAX_JPEG_BYTES,
    MAX_QUALITY,
    MIN_QUALITY,
    FrameRenderer,
    parse_comment,
    quality_for_bitrate,
)

PacketT = TypeVar("PacketT", TelemetryPacket, VideoFramePacket)
SimFactory = Callable[..., RobotSimulator]

WAIT_S = 3.0
RECEIVE_S = 2.0


@pytest.fixture(scope="module")
def profile() -> RobotProfile:
    """The shipped Engineer profile."""
    return load_profile()


class OcuClient:
    """A bare UDP client speaking the vendor protocol, standing in for the OCU."""

    def __init__(self, profile: RobotProfile, target: tuple[str, int]) -> None:
        self.profile = profile
        self.target = target
        self.codec = make_codec(profile)
        self.mapper = CommandMapper(profile)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        host, port = self.sock.getsockname()[:2]
        self.address = (str(host), int(port))

    def send(self, command: Command) -> float:
        """Send the RCP of a command; returns the monotonic send time."""
        sent_s = time.monotonic()
        self.sock.sendto(self.codec.encode(self.mapper.to_packet(command)), self.target)
        return sent_s

    def send_raw(self, data: bytes) -> None:
        """Send arbitrary bytes."""
        self.sock.sendto(data, self.target)

    def receive(self, kind: type[PacketT], timeout_s: float = RECEIVE_S) -> PacketT | None:
        """The next packet of one kind, skipping others; None when the deadline passes."""
        deadline_s = time.monotonic() + timeout_s
        while True:
            remaining_s = deadline_s - time.monotonic()
            if remaining_s <= 0.0:
                return None
            self.sock.settimeout(remaining_s)
            try:
                data = self.sock.recv(70_000)
            except TimeoutError:
                return None
            packet: Packet = self.codec.decode(data)
            if isinstance(packet, kind):
                return packet

    def drain(self) -> None:
        """Discard everything already queued."""
        self.sock.setblocking(False)
        try:
            while True:
                self.sock.recv(70_000)
        except BlockingIOError:
            pass
        finally:
            self.sock.setblocking(True)

    def close(self) -> None:
        """Close the socket."""
        self.sock.close()


@pytest.fixture
def make_sim(profile: RobotProfile) -> Iterator[SimFactory]:
    """Start simulators (fast telemetry, no video unless asked); stopped after the test."""
    sims: list[RobotSimulator] = []

    def factory(**kwargs: Any) -> RobotSimulator:
        kwargs.setdefault("telemetry_hz", 50.0)
        kwargs.setdefault("video_fps", 0.0)
        kwargs.setdefault("seed", 1)
        sim = RobotSimulator(profile, **kwargs)
        sims.append(sim)
        sim.start()
        return sim

    yield factory
    for sim in sims:
        sim.stop()
    for sim in sims:
        assert sim.state().internal_errors == 0


@pytest.fixture
def make_client(profile: RobotProfile) -> Iterator[Callable[[RobotSimulator], OcuClient]]:
    """Clients aimed at a simulator; closed after the test."""
    clients: list[OcuClient] = []

    def factory(sim: RobotSimulator) -> OcuClient:
        client = OcuClient(profile, sim.address)
        clients.append(client)
        return client

    yield factory
    for client in clients:
        client.close()


def wait_for(
    sim: RobotSimulator, predicate: Callable[[SimState], bool], timeout_s: float = WAIT_S
) -> SimState:
    """The first snapshot that satisfies predicate; fails the test on timeout."""
    hits: list[SimState] = []

    def check(state: SimState) -> bool:
        if predicate(state):
            hits.append(state)
            return True
        return False

    assert sim.wait_until(check, timeout_s), "simulator did not reach the expected state"
    return hits[0]


def reached_time(time_s: float) -> Callable[[SimState], bool]:
    """Predicate: the simulation clock reached time_s."""
    return lambda state: state.time_s >= time_s


def received_datagrams(count: int) -> Callable[[SimState], bool]:
    """Predicate: the simulator has read exactly count datagrams."""
    return lambda state: state.datagrams_received == count


def quality_is(quality: int) -> Callable[[dict[str, str]], bool]:
    """Predicate on JPEG comment fields: encoded at this quality."""
    return lambda fields: int(fields["quality"]) == quality


def record_of(profile: RobotProfile, packet: TelemetryPacket, motor: str) -> MotorRecord:
    """The telemetry record of one motor."""
    device_id = profile.motors[motor].device_id
    return next(record for record in packet.motors if record.device_id == device_id)


def receive_telemetry_until(
    client: OcuClient, predicate: Callable[[TelemetryPacket], bool], timeout_s: float = WAIT_S
) -> TelemetryPacket:
    """The first telemetry packet that satisfies predicate; fails the test on timeout."""
    deadline_s = time.monotonic() + timeout_s
    while (remaining_s := deadline_s - time.monotonic()) > 0.0:
        packet = client.receive(TelemetryPacket, remaining_s)
        if packet is not None and predicate(packet):
            return packet
    raise AssertionError("no matching telemetry packet arrived")


def receive_frame_until(
    client: OcuClient, predicate: Callable[[dict[str, str]], bool], timeout_s: float = WAIT_S
) -> tuple[bytes, dict[str, str]]:
    """The first video JPEG whose comment satisfies predicate, with its comment fields."""
    deadline_s = time.monotonic() + timeout_s
    while (remaining_s := deadline_s - time.monotonic()) > 0.0:
        packet = client.receive(VideoFramePacket, remaining_s)
        if packet is None:
            break
        with Image.open(io.BytesIO(packet.jpeg)) as image:
            image.load()
            comment = image.info.get("comment", b"")
        fields = parse_comment(comment)
        if predicate(fields):
            return packet.jpeg, fields
    raise AssertionError("no matching video frame arrived")


# ---- lifecycle --------------------------------------------------------------------------------


def test_defaults_come_from_the_profile(profile: RobotProfile) -> None:
    sim = RobotSimulator(profile)
    try:
        assert sim.telemetry_hz == profile.link.telemetry_rate_hz
        assert sim.address[0] == "127.0.0.1"
        assert sim.address[1] != 0
        assert sim.faults == FaultConfig()
    finally:
        sim.stop()


@pytest.mark.parametrize(
    ("joints", "match"),
    [({"left_track": 0.0}, "not a motor with a position"), ({"neck": 10.0}, "outside")],
)
def test_initial_joints_are_validated(
    profile: RobotProfile, joints: dict[str, float], match: str
) -> None:
    with pytest.raises(ValueError, match=match):
        RobotSimulator(profile, initial_joints=joints)


def test_runs_one_named_daemon_thread_and_stops_idempotently(profile: RobotProfile) -> None:
    with RobotSimulator(profile, video_fps=0.0) as sim:
        threads = [t for t in threading.enumerate() if t.name == "ocu-sim"]
        assert len(threads) == 1
        assert threads[0].daemon
        with pytest.raises(RuntimeError, match="already started"):
            sim.start()
    sim.stop()
    assert not threads[0].is_alive()
    with pytest.raises(RuntimeError, match="already stopped"):
        sim.start()


def test_nothing_is_sent_before_the_first_rcp(
    make_sim: SimFactory, make_client: Callable[[RobotSimulator], OcuClient]
) -> None:
    sim = make_sim(video_fps=20.0)
    client = make_client(sim)
    state = wait_for(sim, lambda s: s.elapsed_s >= 0.3)
    assert state.client is None
    assert state.telemetry_sent == 0
    assert state.video_sent == 0
    assert state.datagrams_sent == 0
    assert client.receive(TelemetryPacket, 0.05) is None


# ---- transports -------------------------------------------------------------------------------


def receive_on_wire(
    wire: VirtualWire, codec: Codec, predicate: Callable[[TelemetryPacket], bool]
) -> TelemetryPacket:
    """The first telemetry packet on the OCU end of a wire that satisfies predicate."""
    buffer = bytearray(70_000)
    deadline_s = time.monotonic() + WAIT_S
    while (remaining_s := deadline_s - time.monotonic()) > 0.0:
        readable, _, _ = select.select([wire.ocu.socket], [], [], remaining_s)
        received = wire.ocu.receive(buffer) if readable else None
        if received is None:
            continue
        size, sender = received
        assert sender == VIRTUAL_ROBOT
        packet = codec.decode(bytes(buffer[:size]))
        if isinstance(packet, TelemetryPacket) and predicate(packet):
            return packet
    raise AssertionError("no matching telemetry packet arrived on the wire")


def test_serves_a_virtual_wire_in_process(profile: RobotProfile) -> None:
    wire = VirtualWire()
    codec, mapper = make_codec(profile), CommandMapper(profile)
    try:
        sim = RobotSimulator(
            profile, transport=wire.robot, telemetry_hz=50.0, video_fps=0.0, seed=1
        )
        with sim:
            assert sim.address == VIRTUAL_ROBOT
            rcp = codec.encode(mapper.to_packet(Command({"shoulder": 0.4})))
            wire.ocu.send(rcp, VIRTUAL_ROBOT)
            moved = wait_for(sim, lambda s: s.joints_rad["shoulder"] >= 0.04)
            assert moved.client == VIRTUAL_OCU
            assert sim.received_commands()[-1].address == VIRTUAL_OCU
            packet = receive_on_wire(
                wire, codec, lambda p: (read_telemetry(profile, p)["shoulder"].angle_rad or 0) > 0
            )
            assert record_of(profile, packet, "shoulder").speed > 0
        state = sim.state()
        assert state.datagrams_received == 1
        assert state.datagrams_sent == state.telemetry_sent > 0
        assert state.internal_errors == 0
        # The wire is its owner's: still open after the simulator stopped.
        wire.ocu.send(rcp, VIRTUAL_ROBOT)
    finally:
        wire.close()


# ---- telemetry --------------------------------------------------------------------------------


def test_telemetry_rate_and_destination_follow_the_latest_sender(
    profile: RobotProfile,
    make_sim: SimFactory,
    make_client: Callable[[RobotSimulator], OcuClient],
) -> None:
    rate_hz = 20.0
    sim = make_sim(telemetry_hz=rate_hz)
    first, second = make_client(sim), make_client(sim)
    first.send(Command())
    ticks = []
    for _ in range(11):
        packet = first.receive(TelemetryPacket)
        assert packet is not None
        ticks.append(packet.tick)
    tick_step = (ticks[-1] - ticks[0]) / (len(ticks) - 1)
    assert tick_step == pytest.approx(profile.link.telemetry_tick_hz / rate_hz, rel=0.1)

    second.send(Command())
    wait_for(sim, lambda s: s.client == second.address)
    first.drain()
    assert second.receive(TelemetryPacket) is not None
    assert first.receive(TelemetryPacket, 0.3) is None


def test_telemetry_decodes_back_to_the_simulator_angles(
    profile: RobotProfile,
    make_sim: SimFactory,
    make_client: Callable[[RobotSimulator], OcuClient],
) -> None:
    initial = {"shoulder": 0.5, "elbow": -1.0, "neck": 0.3}
    sim = make_sim(initial_joints=initial)
    client = make_client(sim)
    client.send(Command())
    packet = client.receive(TelemetryPacket)
    assert packet is not None
    state = sim.state()
    assert len(packet.motors) == len(profile.motors)
    assert 0 < packet.tick <= state.elapsed_s * profile.link.telemetry_tick_hz
    readings = read_telemetry(profile, packet)
    for name, angle_rad in state.joints_rad.items():
        reading = readings[name]
        ticks_per_rad = profile.motors[name].ticks_per_rad
        assert ticks_per_rad is not None
        assert reading.angle_rad == pytest.approx(angle_rad, abs=1.0 / ticks_per_rad)
        assert reading.target_angle_rad == reading.angle_rad
    for name, angle_rad in initial.items():
        assert readings[name].angle_rad == pytest.approx(angle_rad, abs=1e-3)
    for record in packet.motors:
        assert record.state == DEVICE_STATE_OPERATIONAL
        assert record.mode == OPERATION_MODE_VELOCITY
        assert record.speed == 0
        assert record.current > 0
    for motor in profile.motors.values():
        if motor.track is not None:
            record = record_of(profile, packet, motor.name)
            assert record.position == 0
            assert record.position_command == 0


# ---- motion -----------------------------------------------------------------------------------


def test_joint_integrates_at_the_commanded_speed(
    profile: RobotProfile,
    make_sim: SimFactory,
    make_client: Callable[[RobotSimulator], OcuClient],
) -> None:
    sim = make_sim()
    client = make_client(sim)
    client.send(Command({"shoulder": 0.4}))
    moving = wait_for(sim, lambda s: s.velocities["shoulder"] != 0.0)
    later = wait_for(sim, lambda s: s.time_s >= moving.time_s + 0.5)
    speed_rad_s = moving.velocities["shoulder"]
    axis_step = 1.0 / profile.channels["shoulder"].axis_per_unit
    assert speed_rad_s == pytest.approx(0.4, abs=axis_step)
    assert later.velocities["shoulder"] == speed_rad_s
    travelled_rad = later.joints_rad["shoulder"] - moving.joints_rad["shoulder"]
    assert travelled_rad == pytest.approx(speed_rad_s * (later.time_s - moving.time_s), rel=1e-6)

    telemetry = receive_telemetry_until(
        client, lambda p: record_of(profile, p, "shoulder").speed != 0
    )
    record = record_of(profile, telemetry, "shoulder")
    assert record.speed == round(speed_rad_s * profile.telemetry_speed_per_rad_s)
    assert record.speed_command == record.speed
    assert record.current > record_of(profile, telemetry, "elbow").current


def test_joints_stop_at_their_limits_with_status_bits(
    profile: RobotProfile,
    make_sim: SimFactory,
    make_client: Callable[[RobotSimulator], OcuClient],
) -> None:
    neck_limits = profile.motors["neck"].limits_rad
    gripper_limits = profile.motors["gripper"].limits_rad
    assert neck_limits is not None
    assert gripper_limits is not None
    sim = make_sim(initial_joints={"neck": neck_limits[1] - 0.05, "gripper": gripper_limits[0]})
    client = make_client(sim)
    client.send(Command({"neck": 0.5, "gripper": -0.5}))
    state = wait_for(
        sim, lambda s: s.joints_rad["neck"] >= neck_limits[1] and s.rcp_count == 1, timeout_s=0.9
    )
    assert not state.watchdog_stopped
    assert state.joints_rad["neck"] == neck_limits[1]
    assert state.velocities["neck"] == 0.0
    assert state.joints_rad["gripper"] == gripper_limits[0]
    assert state.velocities["gripper"] == 0.0
    assert state.commanded_velocities["neck"] > 0.0

    telemetry = receive_telemetry_until(
        client, lambda p: record_of(profile, p, "neck").status & STATUS_AT_UPPER_LIMIT != 0
    )
    assert record_of(profile, telemetry, "gripper").status & STATUS_AT_LOWER_LIMIT
    assert record_of(profile, telemetry, "neck").status & STATUS_AT_LOWER_LIMIT == 0
    assert record_of(profile, telemetry, "waist").status == 0

    client.send(Command({"neck": -0.5}))
    state = wait_for(sim, lambda s: s.joints_rad["neck"] < neck_limits[1])
    assert state.velocities["neck"] < 0.0


def test_waist_is_ignored_while_the_chassis_moves(
    profile: RobotProfile,
    make_sim: SimFactory,
    make_client: Callable[[RobotSimulator], OcuClient],
) -> None:
    sim = make_sim()
    client = make_client(sim)
    for drive in ({"drive_linear": 0.3}, {"drive_turn": 0.5}):
        sent_s = client.send(Command({**drive, "waist": 0.5}))
        state = wait_for(sim, reached_time(sent_s + 0.2))
        assert state.waist_suppressed
        assert state.velocities["waist"] == 0.0
        assert state.joints_rad["waist"] == 0.0
        assert state.track_speeds_m_s != (0.0, 0.0)
    telemetry = receive_telemetry_until(
        client, lambda p: record_of(profile, p, "waist").status & STATUS_SUPPRESSED != 0
    )
    assert record_of(profile, telemetry, "waist").speed == 0
    assert record_of(profile, telemetry, "waist").speed_command > 0

    client.send(Command({"waist": 0.5}))
    state = wait_for(sim, lambda s: s.joints_rad["waist"] > 0.0)
    assert not state.waist_suppressed
    assert state.velocities["waist"] == pytest.approx(0.5)
    assert state.track_speeds_m_s == (0.0, 0.0)


def test_watchdog_stops_every_motor_within_its_window(
    profile: RobotProfile,
    make_sim: SimFactory,
    make_client: Callable[[RobotSimulator], OcuClient],
) -> None:
    sim = make_sim()
    client = make_client(sim)
    client.send(Command({"shoulder": 0.3, "drive_linear": 0.3}))
    wait_for(sim, lambda s: not s.all_stopped)
    stopped = wait_for(sim, lambda s: s.all_stopped)
    last_rcp_s = sim.received_commands()[-1].time_s
    watchdog_s = profile.link.robot_watchdog_s
    assert watchdog_s <= stopped.time_s - last_rcp_s <= watchdog_s + 0.3
    assert stopped.watchdog_stopped
    assert stopped.track_speeds_m_s == (0.0, 0.0)
    telemetry = receive_telemetry_until(
        client, lambda p: all(r.status & STATUS_WATCHDOG_STOP for r in p.motors)
    )
    assert all(record.speed_command == 0 for record in telemetry.motors)

    client.send(Command({"shoulder": 0.3}))
    resumed = wait_for(sim, lambda s: not s.all_stopped)
    assert not resumed.watchdog_stopped


# ---- video ------------------------------------------------------------------------------------


def test_video_frames_follow_the_camera_button_and_torch(
    profile: RobotProfile,
    make_sim: SimFactory,
    make_client: Callable[[RobotSimulator], OcuClient],
) -> None:
    names = profile.link.camera_names
    sim = make_sim(video_fps=20.0, telemetry_hz=5.0)
    client = make_client(sim)
    client.send(Command())
    jpeg, fields = receive_frame_until(client, lambda f: True)
    with Image.open(io.BytesIO(jpeg)) as image:
        assert image.format == "JPEG"
        assert image.size == (320, 240)
    assert fields["camera"] == names[0]
    assert int(fields["quality"]) == DEFAULT_QUALITY

    last = len(names) - 1
    client.send(Command(camera=last, torch=True))
    state = wait_for(sim, lambda s: s.camera == last)
    assert state.torch
    receive_frame_until(client, lambda f: f["camera"] == names[last] and f["torch"] == "1")
    _, fields = receive_frame_until(client, lambda f: True)
    assert fields["camera"] == names[last]

    client.send(Command(camera=None))
    state = wait_for(sim, lambda s: s.rcp_count == 3)
    assert state.camera == last
    assert not state.torch
    _, next_fields = receive_frame_until(client, lambda f: f["torch"] == "0")
    assert next_fields["camera"] == names[last]
    assert int(next_fields["frame"]) > int(fields["frame"])


def test_video_quality_follows_the_bitrate(
    make_sim: SimFactory, make_client: Callable[[RobotSimulator], OcuClient]
) -> None:
    sim = make_sim(video_fps=20.0, telemetry_hz=5.0)
    client = make_client(sim)
    sizes = {}
    for bitrate in (300_000.0, 1_800_000.0):
        quality = quality_for_bitrate(bitrate)
        client.send(Command(video_bitrate=bitrate))
        jpeg, _ = receive_frame_until(client, quality_is(quality))
        sizes[quality] = len(jpeg)
    low, high = sorted(sizes)
    assert low < high
    assert sizes[high] > 2 * sizes[low]


def test_quality_for_bitrate_is_monotonic_and_clamped() -> None:
    assert quality_for_bitrate(0.0) == DEFAULT_QUALITY
    assert quality_for_bitrate(math.nan) == DEFAULT_QUALITY
    assert quality_for_bitrate(1.0) == MIN_QUALITY
    assert quality_for_bitrate(1e12) == MAX_QUALITY
    qualities = [quality_for_bitrate(1000.0 * step) for step in range(1, 3000)]
    assert qualities == sorted(qualities)


def test_large_frames_still_fit_one_datagram(profile: RobotProfile) -> None:
    renderer = FrameRenderer(profile.link.camera_names, (1600, 1200))
    jpeg = renderer.render(0, 7, MAX_QUALITY, torch=True)
    assert len(jpeg) <= MAX_JPEG_BYTES
    with Image.open(io.BytesIO(jpeg)) as image:
        image.load()
        fields = parse_comment(image.info["comment"])
    assert int(fields["quality"]) < MAX_QUALITY
    with pytest.raises(ValueError, match="frame size"):
        FrameRenderer(profile.link.camera_names, (8, 8))


def test_frames_have_moving_content(profile: RobotProfile) -> None:
    renderer = FrameRenderer(profile.link.camera_names, (160, 120))
    frames = []
    for frame_number in (0, 1):
        jpeg = renderer.render(0, frame_number, DEFAULT_QUALITY, time_s=0.0)
        with Image.open(io.BytesIO(jpeg)) as image:
            frames.append(image.convert("RGB"))
    assert ImageChops.difference(frames[0], frames[1]).getbbox() is not None


# ---- bad input --------------------------------------------------------------------------------


def test_malformed_and_foreign_datagrams_are_counted_and_dropped(
    profile: RobotProfile,
    make_sim: SimFactory,
    make_client: Callable[[RobotSimulator], OcuClient],
) -> None:
    sim = make_sim()
    client = make_client(sim)
    types = profile.link.frame_types
    unknown_type = next(t for t in range(256) if t not in {types.rcp, types.telemetry, types.video})
    valid_rcp = client.codec.encode(client.mapper.to_packet(Command()))
    malformed = [
        b"",
        valid_rcp[:10],
        valid_rcp + b"\0",
        bytes([unknown_type]) + valid_rcp[1:],
        bytes([types.video]) + b"not a jpeg",
    ]
    foreign = [
        client.codec.encode(TelemetryPacket()),
        client.codec.encode(VideoFramePacket(jpeg=b"\xff\xd8\xff\xff\xd9")),
    ]
    for data in malformed + foreign:
        client.send_raw(data)
    total = len(malformed) + len(foreign)
    state = wait_for(sim, lambda s: s.datagrams_received == total)
    assert state.malformed_count == len(malformed)
    assert state.foreign_count == len(foreign)
    assert state.rcp_count == 0
    assert state.client is None

    client.send_raw(valid_rcp)
    assert client.receive(TelemetryPacket) is not None
    assert sim.state().rcp_count == 1


# ---- faults -----------------------------------------------------------------------------------


def test_fault_config_and_set_faults_validate(make_sim: SimFactory) -> None:
    with pytest.raises(ValueError, match="loss"):
        FaultConfig(loss=1.5)
    with pytest.raises(ValueError, match="latency_ms"):
        FaultConfig(latency_ms=-1.0)
    sim = make_sim()
    with pytest.raises(ValueError, match="duplicate"):
        sim.set_faults(duplicate=-0.1)
    sim.set_faults(loss=0.1, jitter_ms=5.0)
    sim.set_faults(latency_ms=20.0)
    assert sim.faults == FaultConfig(loss=0.1, latency_ms=20.0, jitter_ms=5.0)


def test_loss_drops_about_the_configured_fraction(
    make_sim: SimFactory, make_client: Callable[[RobotSimulator], OcuClient]
) -> None:
    loss = 0.3
    sim = make_sim(telemetry_hz=200.0, seed=7)
    client = make_client(sim)
    client.send(Command())
    wait_for(sim, lambda s: s.rcp_count == 1)
    sim.set_faults(loss=loss)
    count = 400
    for batch in range(count // 50):
        for _ in range(50):
            client.send(Command())
        expected = 1 + (batch + 1) * 50
        wait_for(sim, received_datagrams(expected))
    state = sim.state()
    assert state.rcp_count - 1 + state.dropped_to_robot == count
    sigma = math.sqrt(count * loss * (1.0 - loss))
    assert abs(state.dropped_to_robot - count * loss) <= 4.0 * sigma

    start_sent, start_dropped = state.telemetry_sent, state.dropped_to_ocu
    state = wait_for(sim, lambda s: s.telemetry_sent >= start_sent + 200)
    sent = state.telemetry_sent - start_sent
    dropped = state.dropped_to_ocu - start_dropped
    assert abs(dropped - sent * loss) <= 4.0 * math.sqrt(sent * loss * (1.0 - loss)) + 2


def test_duplicate_sends_every_datagram_twice(
    make_sim: SimFactory, make_client: Callable[[RobotSimulator], OcuClient]
) -> None:
    sim = make_sim(faults=FaultConfig(duplicate=1.0))
    client = make_client(sim)
    for _ in range(10):
        client.send(Command())
    state = wait_for(sim, lambda s: s.rcp_count == 20)
    assert len(sim.received_commands()) == 20
    ticks = []
    for _ in range(8):
        packet = client.receive(TelemetryPacket)
        assert packet is not None
        ticks.append(packet.tick)
    assert len(set(ticks)) <= 5
    assert state.duplicated >= 10


def test_latency_delays_both_directions(
    make_sim: SimFactory, make_client: Callable[[RobotSimulator], OcuClient]
) -> None:
    latency_s = 0.15
    sim = make_sim(telemetry_hz=100.0)
    sim.set_faults(latency_ms=latency_s * 1000.0, jitter_ms=20.0)
    client = make_client(sim)
    sent_s = client.send(Command())
    assert client.receive(TelemetryPacket) is not None
    received_s = time.monotonic()
    delivered_s = sim.received_commands()[-1].time_s
    assert delivered_s - sent_s >= latency_s
    assert received_s - delivered_s >= latency_s
    assert received_s - sent_s >= 2 * latency_s


def test_cut_link_drops_everything_until_restored(
    make_sim: SimFactory, make_client: Callable[[RobotSimulator], OcuClient]
) -> None:
    sim = make_sim()
    client = make_client(sim)
    client.send(Command({"shoulder": 0.3}))
    assert client.receive(TelemetryPacket) is not None

    cut_s = time.monotonic()
    sim.cut_link()
    # Once a step after the cut is published, no send that began before it can still land.
    wait_for(sim, lambda s: s.time_s > cut_s and s.link_cut)
    client.drain()
    for _ in range(3):
        client.send(Command({"shoulder": 0.3}))
    state = wait_for(sim, lambda s: s.datagrams_received == 4)
    assert state.rcp_count == 1
    assert state.dropped_to_robot == 3
    assert client.receive(TelemetryPacket, 0.3) is None
    stopped = wait_for(sim, lambda s: s.watchdog_stopped)
    assert stopped.all_stopped
    assert stopped.dropped_to_ocu > 0

    sim.restore_link()
    client.send(Command({"shoulder": 0.3}))
    assert client.receive(TelemetryPacket) is not None
    state = wait_for(sim, lambda s: not s.all_stopped)
    assert state.rcp_count == 2
    assert not state.link_cut
