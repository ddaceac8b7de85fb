"""Click-to-track in the console model, no Qt and no sockets: the source it owns, the direction
it turns, the stop when frames stop or the object stays lost, and any operator input ending it."""

from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np
import pytest

from ocu.console.model import ConsoleModel, Source
from ocu.console.tracking import FRAME_TIMEOUT_S, LOST_TIMEOUT_S
from ocu.profile import RobotProfile
from ocu.records import CommandError
from tests.console.test_model import frame, reading

WIDTH, HEIGHT = 320, 240


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def picture(at_x: int) -> np.ndarray:
    """A grey, lightly textured scene with a patterned red square whose left edge is at at_x."""
    rng = np.random.default_rng(4)
    image = cv2.GaussianBlur(rng.integers(90, 160, (HEIGHT, WIDTH, 3), dtype=np.uint8), (0, 0), 2)
    cv2.rectangle(image, (at_x, 100), (at_x + 30, 130), (30, 30, 220), -1)
    cv2.rectangle(image, (at_x + 6, 106), (at_x + 14, 114), (255, 255, 255), -1)
    cv2.rectangle(image, (at_x + 18, 116), (at_x + 24, 124), (0, 0, 0), -1)
    return image


def setup(profile: RobotProfile) -> tuple[ConsoleModel, Clock, int, list[str]]:
    clock = Clock()
    model = ConsoleModel(profile, clock=clock)
    assert profile.arm is not None
    model.on_telemetry(
        frame({j: reading(profile, j, 0.0) for j in profile.arm.joints}, clock.now, 0.02)
    )
    head = next(
        i for i, c in enumerate(profile.cameras) if c.mount is not None and c.mount.link is not None
    )
    messages: list[str] = []
    model.events.message.connect(messages.append)
    return model, clock, head, messages


def test_an_object_right_of_the_centre_turns_the_waist_right_and_silence_stops_it(
    profile: RobotProfile,
) -> None:
    model, clock, head, messages = setup(profile)
    square = 220  # right of the centre
    model.start_tracking(head, picture(square), ((square + 15) / WIDTH, 115 / HEIGHT))
    session = model.tracking_session
    assert session is not None
    pan, tilt = session.channels
    assert model.channel(pan).source is Source.TRACK
    assert model.channel(tilt).source is Source.TRACK
    for _ in range(3):
        clock.now += 0.05
        model.on_tracking_frame(head, picture(square), clock.now)
        model.update()
    assert model.velocities().get(pan, 0.0) < 0.0  # + waist is left: right is -
    assert abs(model.velocities().get(pan, 0.0)) <= model.limits.get(pan)
    # No more frames: the joints stop, and the tracking ends once the object counts as lost.
    clock.now += FRAME_TIMEOUT_S + 0.05
    model.update()
    assert model.velocities().get(pan, 0.0) == 0.0
    assert model.tracking is not None
    clock.now += LOST_TIMEOUT_S
    model.update()
    assert model.tracking is None
    assert model.channel(pan).source is Source.NONE
    assert any("tracking stopped: object lost" in m for m in messages)


@pytest.mark.parametrize(
    "act",
    [
        lambda m: m.set_velocity("drive_linear", 0.1),
        lambda m: m.hotkey_down("Q", "waist", 1),
        lambda m: m.emergency_stop("Space"),
        lambda m: m.halt("link lost"),
    ],
    ids=["slider elsewhere", "key on the waist", "space", "halt"],
)
def test_any_operator_input_or_stop_ends_it(
    profile: RobotProfile, act: Callable[[ConsoleModel], object]
) -> None:
    model, _clock, head, messages = setup(profile)
    model.start_tracking(head, picture(220), (235 / WIDTH, 115 / HEIGHT))
    act(model)
    assert model.tracking is None
    assert all(c.source is not Source.TRACK for c in model.channels.values())
    assert any(m.startswith("tracking stopped") for m in messages)


def test_a_camera_on_the_chassis_and_a_plain_wall_are_refused(profile: RobotProfile) -> None:
    model, _clock, head, _messages = setup(profile)
    chassis = next(i for i, c in enumerate(profile.cameras) if c.mount and not c.mount.link)
    with pytest.raises(CommandError, match="not on the arm"):
        model.start_tracking(chassis, picture(220), (0.7, 0.5))
    plain = np.full((HEIGHT, WIDTH, 3), 128, np.uint8)
    with pytest.raises(CommandError, match="plain surface"):
        model.start_tracking(head, plain, (0.5, 0.5))
    assert model.tracking is None
    assert not model.is_moving
