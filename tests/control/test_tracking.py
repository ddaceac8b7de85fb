"""The tracking PID: delay-adapted gains and the Smith-corrected error, on a simulated joint."""

from __future__ import annotations

import math
from collections import deque

import pytest

from ocu.control.tracking import (
    KP_MAX,
    CameraAxes,
    TrackingController,
    TrackingOptions,
    gains_for_delay,
)

DT = 0.02
FOCAL = 300.0
AXES = CameraAxes("waist", "neck", (FOCAL, FOCAL), (640, 480))


def test_gains_fall_with_the_delay_and_keep_a_60_degree_margin() -> None:
    assert gains_for_delay(0.0).kp == KP_MAX
    slow, slower = gains_for_delay(0.2), gains_for_delay(0.4)
    assert slower.kp < slow.kp < KP_MAX
    for delay in (0.1, 0.2, 0.4, 1.0):
        assert gains_for_delay(delay).kp * delay <= math.pi / 6 + 1e-9
    assert gains_for_delay(None).kp == gains_for_delay(0.5).kp  # unknown: cautious


def simulate(
    delay_s: float, object_speed_rad_s: float, seconds: float, *, smith: bool = True
) -> list[float]:
    """Pan error (rad) over time: a joint commanded in velocity, frames `delay_s` old, the
    object turning at `object_speed_rad_s` around the camera (the chassis turning)."""
    controller = TrackingController(AXES, (0.8, 0.8))
    steps = round(delay_s / 2 / DT)
    commands: deque[float] = deque([0.0] * (steps + 1))  # on the way to the robot
    joint = 0.0
    object_angle = math.radians(10.0)
    frames: deque[tuple[float, float, float]] = deque()  # (taken at, x, angle) coming back
    errors = []
    known = 0.0
    now = 0.0
    for _ in range(round(seconds / DT)):
        now += DT
        object_angle += object_speed_rad_s * DT
        # The robot applies what arrives; its camera takes a frame.
        joint += commands.popleft() * DT
        x = 0.5 + FOCAL * math.tan(joint - object_angle) / 640
        frames.append((now, x, joint))
        # The OCU: where the joint ends once what was sent has landed (or, without the
        # prediction, the last angle it knows).
        in_flight = sum(commands) * DT if smith else 0.0
        while frames and frames[0][0] <= now - delay_s:
            taken_at, seen_x, angle = frames.popleft()
            known = angle
            controller.on_measurement((seen_x, 0.5), taken_at, {"waist": angle, "neck": 0.0})
        eventual = {"waist": (joint + in_flight) if smith else known, "neck": 0.0}
        velocity = controller.update(now, eventual, delay_s).get("waist", 0.0)
        commands.append(velocity)
        errors.append(object_angle - joint)
    return errors


@pytest.mark.parametrize("delay_s", [0.0, 0.15, 0.4])
def test_centres_a_still_object_without_overshoot_at_any_delay(delay_s: float) -> None:
    errors = simulate(delay_s, 0.0, 6.0)
    assert abs(errors[-1]) < math.radians(0.5)
    # It starts 10° off (positive): never more than 1° past the object.
    assert min(errors) > -math.radians(1.0)


def test_follows_the_chassis_turning_at_0_3_rad_s_with_150_ms_of_delay() -> None:
    errors = simulate(0.15, 0.3, 10.0)
    steady = errors[len(errors) // 2 :]
    rms = math.sqrt(sum(e * e for e in steady) / len(steady))
    assert rms < math.radians(1.0)


def test_without_the_prediction_the_same_gains_ring() -> None:
    # The Smith correction is what lets the gains be this high: without it, the same loop
    # overshoots (the test would pass with it removed only if it did nothing).
    with_prediction = simulate(0.4, 0.0, 6.0)
    without = simulate(0.4, 0.0, 6.0, smith=False)
    assert min(without) < min(with_prediction) - math.radians(0.5)


def test_no_target_no_motion_and_stop_forgets() -> None:
    controller = TrackingController(AXES, (0.8, 0.8))
    still = {"waist": 0.0, "neck": 0.0}
    assert controller.update(0.0, still, 0.1) == {}
    assert controller.on_measurement((0.9, 0.5), 0.0, still)
    assert controller.update(0.02, still, 0.1)["waist"] < 0  # on the right: turn right
    controller.stop()
    assert controller.update(0.04, still, 0.1) == {}
    # Without the joints' angles at the frame's moment nothing can be placed.
    assert not controller.on_measurement((0.5, 0.5), 0.1, {"waist": 0.0})


def test_the_baseline_acts_on_the_last_frame_with_the_no_delay_gains() -> None:
    """The benchmark's baseline (the paper's PID): the image error of the last frame, whatever
    is on its way to the joint, at the gains for no delay."""
    baseline = TrackingController(AXES, (0.8, 0.8), TrackingOptions.baseline())
    ours = TrackingController(AXES, (0.8, 0.8))
    for controller in (baseline, ours):
        controller.on_measurement((0.55, 0.5), 0.0, {"waist": 0.0, "neck": 0.0})
    offset = -math.atan2(0.05 * 640, FOCAL)  # right of the centre: the waist turns right
    eventual = {"waist": offset, "neck": 0.0}  # commands already sent will get there
    assert baseline.update(0.1, eventual, 0.4)["waist"] == pytest.approx(KP_MAX * offset)
    assert abs(ours.update(0.1, eventual, 0.4)["waist"]) < 1e-9  # nothing more to send
