"""The simulator in a world: collisions, the range sensor and the IMU over the extension, and
cameras that draw the world as the robot moves."""

from __future__ import annotations

import logging
import math
import queue
from pathlib import Path

import numpy as np
import pytest

from ocu.link.live import UdpLink
from ocu.model.urdf import load_urdf
from ocu.nav.geometry import Pose
from ocu.nav.world import load_world, parse_world
from ocu.profile import RobotProfile
from ocu.records import Command, LinkEvent, ScanFrame, StatusFrame
from ocu.sim.cli import main
from ocu.sim.physics import RobotPhysics
from ocu.sim.scene import CameraLinks, WorldView
from ocu.sim.simulator import RobotSimulator

WALL_AHEAD = {
    "wall": [{"from_m": [2.0, -3.0], "to_m": [2.0, 3.0]}],
    "start": {"xy_m": [0.0, 0.0], "heading_deg": 0.0},
}
DEADLINE_S = 5.0


def test_the_robot_stops_at_a_wall_and_says_so_once(
    profile: RobotProfile, caplog: pytest.LogCaptureFixture
) -> None:
    physics = RobotPhysics(profile, now_s=0.0, world=parse_world(WALL_AHEAD))
    forward = Command({"drive_linear": 0.4})
    caplog.set_level(logging.WARNING, logger="ocu.sim")
    t = 0.0
    while t < 6.0:
        physics.apply(forward, t)  # a command every 0.1 s, as a link sends them
        t += 0.1
        physics.advance(t)
    x, _y, _heading = physics.pose
    # The wall's face is at 1.95; the footprint reaches 0.62 ahead of the turn centre.
    assert x == pytest.approx(1.95 - 0.62, abs=0.011)
    assert physics.in_contact
    assert physics.collisions == 1
    assert physics.track_speeds_m_s == (0.0, 0.0)  # stalled, as telemetry will say
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert warnings == [f"collision at ({x:.2f}, 0.00)"]
    # Backing away frees it.
    physics.apply(Command({"drive_linear": -0.4}), t)
    physics.advance(t + 1.0)
    assert physics.pose[0] < x - 0.3
    assert not physics.in_contact


def test_a_start_inside_an_obstacle_is_refused(profile: RobotProfile) -> None:
    world = parse_world({**WALL_AHEAD, "start": {"xy_m": [1.6, 0.0]}})
    with pytest.raises(ValueError, match="overlaps a wall"):
        RobotPhysics(profile, world=world)


def test_scans_and_heading_arrive_over_the_extension(profile: RobotProfile) -> None:
    world = load_world("default")
    events: queue.Queue[LinkEvent] = queue.Queue()
    with RobotSimulator(profile, extended=True, world=world, video_fps=0.0, seed=1) as sim:
        extension = sim.extension
        assert extension is not None
        for camera in range(len(profile.link.camera_names)):
            extension.stop_camera(camera)  # keep the cores for the scans
        with UdpLink(profile, sim.address, extension=True) as link:
            link.subscribe(events.put)
            link.start()
            scan = status = None
            while scan is None or status is None or status.yaw_rad is None:
                event = events.get(timeout=DEADLINE_S)
                if isinstance(event, ScanFrame):
                    scan = event
                elif isinstance(event, StatusFrame):
                    status = event
    assert len(scan.ranges_m) == 360
    ranges = np.asarray(scan.ranges_m)
    angles = np.asarray(
        scan.angle_min_rad + scan.angle_increment_rad * np.arange(360), dtype=np.float64
    )
    ahead = ranges[np.argmin(np.abs(angles))]
    # The east wall's face is 4.95 m ahead; noise 1 cm.
    assert ahead == pytest.approx(4.95, abs=0.05)
    truth = world.ray_cast((0.0, 0.0), angles, 8.0)
    assert np.nanmax(np.abs(ranges - truth)) < 0.06
    assert status.yaw_rad == pytest.approx(0.0, abs=0.01)


def test_the_cameras_draw_the_world_from_their_mounts(profile: RobotProfile) -> None:
    world = parse_world(
        {"box": [{"centre_m": [1.5, 0.0], "size_m": [0.6, 0.6], "colour": [250, 20, 20]}]}
    )
    view = WorldView(world)
    front = profile.cameras[0].mount
    facing = view.render(Pose(0.0, 0.0, 0.0), front, (160, 120), (80.0, 80.0))
    away = view.render(Pose(0.0, 0.0, math.pi), front, (160, 120), (80.0, 80.0))

    def red(image: np.ndarray) -> np.ndarray:
        b, g, r = (image[..., k].astype(int) for k in range(3))
        return (r > 100) & (r > 2 * g) & (r > 2 * b)

    assert red(facing)[25:65, 60:100].mean() > 0.9  # the box fills the middle of the view
    assert not red(away).any()


def test_a_bad_world_file_is_an_argparse_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "room.toml"
    bad.write_text("[[box]]\ncentre_m = [0, 0]\nsize = [1, 1]\n", encoding="utf-8")
    with pytest.raises(SystemExit) as exit_info:
        main(["--port", "0", "--world", str(bad)])
    assert exit_info.value.code == 2
    assert "box[0].size: unknown key; did you mean 'size_m'?" in capsys.readouterr().err


def test_a_camera_on_the_head_turns_with_the_waist_and_tilts_with_the_neck(
    profile: RobotProfile,
) -> None:
    world = parse_world(
        {"box": [{"centre_m": [2.5, 0.0], "size_m": [0.4, 0.4], "colour": [250, 20, 20]}]}
    )
    zoom = next(c for c in profile.cameras if c.mount is not None and c.mount.link is not None)
    assert zoom.mount is not None
    assert profile.arm is not None
    view = WorldView(world, CameraLinks(load_urdf(meshes=False).tree, profile.arm.base_link))

    def centroid(joints: dict[str, float]) -> tuple[float, float]:
        image = view.render(
            Pose(0.0, 0.0, 0.0), zoom.mount, (160, 120), (80.0, 80.0), joints_rad=joints
        )
        b, g, r = (image[..., k].astype(int) for k in range(3))
        ys, xs = np.nonzero((r > 100) & (r > 2 * g) & (r > 2 * b))
        assert xs.size > 20, "the box is out of view"
        return float(xs.mean()), float(ys.mean())

    waist, neck = profile.arm.joints[0], profile.arm.joints[-1]
    straight = centroid({})
    assert abs(straight[0] - 80.0) < 3.0  # the head looks straight ahead at the box
    left = centroid({waist: 0.2})
    # The head turned left (+ waist about z): the box moves right in the image, by more than
    # the focal length times the angle (the head, ~1 m forward of the waist, also swings left).
    assert 80.0 * math.tan(0.2) < left[0] - straight[0] < 80.0 * math.tan(0.4)
    assert abs(left[1] - straight[1]) < 2.0
    tilted = centroid({neck: 0.1})
    assert abs(tilted[1] - straight[1]) > 4.0
    assert abs(tilted[0] - straight[0]) < 2.0
