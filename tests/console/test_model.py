"""The operator model without Qt: sources, hotkeys, Shift, e-stop latch, position merging."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace

import pytest
from hypothesis import given
from hypothesis import strategies as st

from ocu.console.events import Event
from ocu.console.model import ChannelCommand, ConsoleModel, Source
from ocu.control.position import PositionError
from ocu.profile import RobotProfile, load_profile
from ocu.protocol import TelemetryPacket
from ocu.records import Command, CommandError, JointReading, TelemetryFrame


class Recorder:
    """Collects every event of a model."""

    def __init__(self, model: ConsoleModel) -> None:
        self.commands: list[dict[str, float]] = []
        self.estops: list[str] = []
        self.estop_states: list[bool] = []
        self.messages: list[str] = []
        self.position_messages: list[str] = []
        self.channels: list[tuple[str, ChannelCommand]] = []
        events = model.events
        events.command_changed.connect(lambda: self.commands.append(model.velocities()))
        events.estop_requested.connect(self.estops.append)
        events.estop_changed.connect(lambda active, _reason: self.estop_states.append(active))
        events.message.connect(self.messages.append)
        events.position_message.connect(self.position_messages.append)
        events.channel_changed.connect(lambda name, cmd: self.channels.append((name, cmd)))


@pytest.fixture
def model(profile: RobotProfile) -> ConsoleModel:
    return ConsoleModel(profile)


def frame(
    readings: dict[str, JointReading], received_at: float, delay_s: float | None = None
) -> TelemetryFrame:
    """A telemetry frame as the link makes it (the packet itself does not matter here)."""
    return TelemetryFrame(TelemetryPacket(tick=0), readings, received_at, 0.0, delay_s)


def reading(profile: RobotProfile, name: str, angle_rad: float) -> JointReading:
    motor = profile.motors[name]
    return JointReading(name, motor.device_id, 1, 2, angle_rad, 0.0, 0.3, 0, angle_rad, 0.0, 0.3)


def test_slider_sets_one_channel_bounded_by_its_maximum(model: ConsoleModel) -> None:
    log = Recorder(model)
    limit = model.max_velocity("waist")
    assert model.set_velocity("waist", 10.0) == limit
    assert model.channel("waist") == ChannelCommand(limit, Source.SLIDER)
    assert log.commands == [{"waist": limit}]
    assert model.set_velocity("waist", -10.0) == -limit


def test_typed_values_apply_together_and_all_or_nothing(model: ConsoleModel) -> None:
    log = Recorder(model)
    model.set_velocities({"waist": 0.1, "elbow": -0.2}, Source.TEXT)
    assert model.velocities() == {"waist": 0.1, "elbow": -0.2}
    assert len(log.commands) == 1  # one command for both: they move together
    with pytest.raises(CommandError, match="finite"):
        model.set_velocities({"waist": 0.3, "neck": math.nan})
    with pytest.raises(CommandError, match="unknown"):
        model.set_velocities({"waist": 0.3, "tail": 1.0})
    assert model.velocities() == {"waist": 0.1, "elbow": -0.2}


def test_hold_to_move_release_to_stop_and_two_keys_at_once(model: ConsoleModel) -> None:
    speed_linear = model.hotkey_speed("drive_linear")
    speed_waist = model.hotkey_speed("waist")
    assert model.hotkey_down("W", "drive_linear", 1)
    assert model.hotkey_down("Q", "waist", 1)
    assert model.velocities() == {"drive_linear": speed_linear, "waist": speed_waist}
    assert not model.hotkey_down("W", "drive_linear", 1)  # already held
    assert model.hotkey_up("W")
    assert model.velocities() == {"waist": speed_waist}
    assert model.channel("drive_linear") == ChannelCommand(0.0, Source.NONE)
    assert model.hotkey_up("Q")
    assert model.velocities() == {}
    assert not model.hotkey_up("Q")


def test_opposite_keys_cancel_and_the_last_release_stops(model: ConsoleModel) -> None:
    model.hotkey_down("W", "drive_linear", 1)
    model.hotkey_down("S", "drive_linear", -1)
    assert model.channel("drive_linear").velocity == 0.0
    model.hotkey_up("W")
    assert model.channel("drive_linear").velocity == -model.hotkey_speed("drive_linear")


def test_hotkey_speed_defaults_to_the_maximum_and_is_bounded_by_it(model: ConsoleModel) -> None:
    assert model.hotkey_speed("waist") == model.max_velocity("waist")
    assert model.set_hotkey_speed("waist", 0.1) == 0.1
    model.hotkey_down("Q", "waist", 1)
    assert model.channel("waist").velocity == 0.1
    model.set_max_velocity("waist", 0.05)  # a lower maximum cuts the held key's speed
    assert model.channel("waist").velocity == 0.05
    model.set_max_velocity("waist", 0.8)
    assert model.channel("waist").velocity == 0.1
    model.set_hotkey_speed("waist", None)
    assert model.channel("waist").velocity == 0.8


def test_max_velocity_never_exceeds_the_hard_maximum(
    model: ConsoleModel, profile: RobotProfile
) -> None:
    hard = profile.channels["drive_linear"].hard_max
    assert model.set_max_velocity("drive_linear", 10.0) == hard
    model.set_velocity("drive_linear", 10.0)
    assert model.channel("drive_linear").velocity == hard
    model.set_max_velocity("drive_linear", 0.1)
    assert model.channel("drive_linear").velocity == 0.1  # the standing command is cut


def test_shift_moves_at_a_fraction_but_not_below_the_servo_deadband(
    model: ConsoleModel, profile: RobotProfile
) -> None:
    model.hotkey_down("Q", "waist", 1)
    model.set_fine(True)
    assert model.channel("waist").velocity == pytest.approx(
        model.hotkey_speed("waist") * model.fine_factor
    )
    model.set_fine(False)
    assert model.channel("waist").velocity == model.hotkey_speed("waist")
    # Drive: a quarter of 0.3 m/s is below the 0.2 m/s at which the servos start moving.
    model.set_fine(True)
    model.hotkey_down("W", "drive_linear", 1)
    assert model.channel("drive_linear").velocity == profile.channels["drive_linear"].min_speed


def test_emergency_stop_zeroes_everything_and_latches(model: ConsoleModel) -> None:
    log = Recorder(model)
    model.set_velocity("waist", 0.3)
    model.hotkey_down("W", "drive_linear", 1)
    model.set_switch("gripper", 1)
    model.set_target("shoulder", 0.5)
    model.emergency_stop("test")
    assert log.estops == ["test"]
    assert model.estopped
    assert model.velocities() == {}
    assert model.held_keys == frozenset()
    assert model.targets == {}
    assert all(c == ChannelCommand() for c in model.channels.values())
    # Nothing resumes by itself: a release, Shift, a control step.
    model.hotkey_up("W")
    model.set_fine(True)
    model.update(1.0)
    assert model.velocities() == {}
    assert model.estopped
    # The operator acts again: a new key press.
    model.hotkey_down("A", "drive_turn", 1)
    assert not model.estopped
    assert model.velocities() == {"drive_turn": model.fine_speed("drive_turn")}
    assert log.estop_states == [True, False]


@pytest.mark.parametrize(
    "act",
    [
        lambda m: m.set_velocity("waist", 0.1),
        lambda m: m.set_velocities({"waist": 0.1}),
        lambda m: m.set_switch("flippers", -1),
        lambda m: m.set_target("waist", 0.2),
    ],
    ids=["slider", "accept", "switch", "target"],
)
def test_every_operator_act_releases_the_latch(
    model: ConsoleModel, act: Callable[[ConsoleModel], None]
) -> None:
    model.emergency_stop()
    act(model)
    assert not model.estopped


def test_halt_stops_without_latching_or_estop(model: ConsoleModel) -> None:
    log = Recorder(model)
    model.hotkey_down("W", "drive_linear", 1)
    model.set_velocity("neck", 0.2)
    assert model.halt("window hidden")
    assert model.velocities() == {}
    assert not model.estopped
    assert log.estops == []
    assert log.messages[-1] == "motion stopped: window hidden"
    assert not model.halt("again")  # nothing to stop: no message
    assert log.messages[-1] == "motion stopped: window hidden"


def test_switch_moves_at_the_hotkey_speed(model: ConsoleModel) -> None:
    model.set_hotkey_speed("flippers", 0.2)
    model.set_switch("flippers", -1)
    assert model.channel("flippers") == ChannelCommand(-0.2, Source.SWITCH)
    model.set_switch("flippers", 0)
    assert model.channel("flippers") == ChannelCommand()
    with pytest.raises(ValueError, match="direction"):
        model.set_switch("flippers", 2)


def test_manual_command_drops_held_keys_of_that_channel(model: ConsoleModel) -> None:
    model.hotkey_down("Q", "waist", 1)
    model.set_velocity("waist", -0.1)
    assert model.held_keys == frozenset()
    assert not model.hotkey_up("Q")  # its release no longer stops the slider's command
    assert model.channel("waist") == ChannelCommand(-0.1, Source.SLIDER)


def test_the_model_owns_the_whole_command_and_switches_survive_an_estop(
    model: ConsoleModel,
) -> None:
    commands: list[Command] = []
    model.events.command_changed.connect(lambda: commands.append(model.command()))
    model.set_torch(True)
    model.select_camera(2)
    model.set_video_bitrate(5.0)
    model.set_velocity("waist", 0.2)
    assert model.command() == Command({"waist": 0.2}, torch=True, camera=2, video_bitrate=5.0)
    assert len(commands) == 4  # each change is published
    model.emergency_stop()
    assert model.command() == Command({}, torch=True, camera=2, video_bitrate=5.0)
    with pytest.raises(CommandError, match="camera 9"):
        model.select_camera(9)
    with pytest.raises(CommandError, match="bit-rate"):
        model.set_video_bitrate(-1.0)


def test_connection_request_halts_before_disconnecting(model: ConsoleModel) -> None:
    seen: list[tuple[bool, dict[str, float]]] = []
    model.events.connection_changed.connect(lambda c: seen.append((c, model.velocities())))
    model.set_velocity("waist", 0.2)
    model.set_connected(False)
    assert seen == [(False, {})]
    model.set_connected(True)
    assert seen[-1] == (True, {})


# ---- position control merged into the channels --------------------------------------------


def test_position_targets_drive_their_channels_and_several_move_at_once(
    model: ConsoleModel, profile: RobotProfile
) -> None:
    log = Recorder(model)
    model.on_telemetry(
        frame({name: reading(profile, name, 0.0) for name in ("waist", "shoulder")}, 0.0)
    )
    model.set_targets({"waist": 0.5, "shoulder": -0.1})
    model.update(0.01)
    assert model.channel("waist").source is Source.POSITION
    assert model.channel("waist").velocity > 0.0
    assert model.channel("shoulder").velocity < 0.0
    assert set(model.targets) == {"waist", "shoulder"}
    # A manual command on a joint takes it back from the controller; the other goes on.
    model.hotkey_down("Q", "waist", -1)
    assert set(model.targets) == {"shoulder"}
    assert model.channel("waist").source is Source.HOTKEY
    model.update(0.02)
    assert model.channel("waist").source is Source.HOTKEY
    assert model.channel("shoulder").source is Source.POSITION
    assert any("cancelled by manual command" in m for m in log.messages)


def test_reached_target_stops_its_channel_with_a_message(
    model: ConsoleModel, profile: RobotProfile
) -> None:
    log = Recorder(model)
    model.on_telemetry(frame({"neck": reading(profile, "neck", 0.0)}, 0.0))
    model.set_target("neck", 0.0005)
    model.update(0.01)
    model.on_telemetry(frame({"neck": reading(profile, "neck", 0.0005)}, 0.05))
    model.update(0.06)
    assert model.targets == {}
    assert model.channel("neck") == ChannelCommand()
    assert any("reached" in m for m in log.position_messages)


def test_bad_target_applies_nothing(model: ConsoleModel) -> None:
    with pytest.raises(PositionError, match="outside the limits"):
        model.set_targets({"waist": 0.1, "shoulder": math.radians(170.0)})
    with pytest.raises(PositionError, match="not a joint driven"):
        model.set_targets({"left_track": 0.1})
    assert model.targets == {}


def test_cancel_targets_stops_the_channels(model: ConsoleModel, profile: RobotProfile) -> None:
    model.on_telemetry(frame({"elbow": reading(profile, "elbow", 0.0)}, 0.0))
    model.set_target("elbow", 1.0)
    model.update(0.01)
    assert model.is_moving
    model.cancel_targets()
    assert not model.is_moving
    assert model.channel("elbow") == ChannelCommand()


# ---- invariants ----------------------------------------------------------------------------

_CHANNELS = ("drive_linear", "drive_turn", "waist", "gripper")
Op = Callable[[ConsoleModel], object]


def _down(key: str, channel: str, direction: int) -> Op:
    return lambda m: m.hotkey_down(key, channel, direction)


def _up(key: str) -> Op:
    return lambda m: m.hotkey_up(key)


def _slider(channel: str, value: float) -> Op:
    return lambda m: m.set_velocity(channel, value)


def _max(channel: str, value: float) -> Op:
    return lambda m: m.set_max_velocity(channel, value)


def _fine(on: bool) -> Op:
    return lambda m: m.set_fine(on)


def _estop() -> Op:
    return lambda m: m.emergency_stop()


_keys = st.sampled_from("WSAQEG")
_channels = st.sampled_from(_CHANNELS)
_ops = st.one_of(
    st.builds(_down, _keys, _channels, st.sampled_from([-1, 1])),
    st.builds(_up, _keys),
    st.builds(_slider, _channels, st.floats(-5, 5)),
    st.builds(_max, _channels, st.floats(0, 5)),
    st.builds(_fine, st.booleans()),
    st.builds(_estop),
)


@given(st.lists(_ops, max_size=30))
def test_velocities_stay_within_the_maxima_and_stop_when_keys_are_up(ops: list[Op]) -> None:
    model = ConsoleModel(load_profile())
    for op in ops:
        op(model)
        for name, value in model.velocities().items():
            assert abs(value) <= model.max_velocity(name) + 1e-12
        if model.estopped:
            assert model.velocities() == {}
    model.release_hotkeys()
    assert all(c.source is not Source.HOTKEY for c in model.channels.values())


def test_event_runs_every_callback_before_raising() -> None:
    event: Event[[int]] = Event()
    seen: list[int] = []

    def broken(_value: int) -> None:
        raise RuntimeError("view failed")

    event.connect(broken)
    event.connect(seen.append)
    with pytest.raises(RuntimeError, match="view failed"):
        event.emit(3)
    assert seen == [3]
    event.disconnect(broken)
    event.emit(4)
    assert seen == [3, 4]


def test_the_drive_pair_keeps_its_turn_radius(model: ConsoleModel, profile: RobotProfile) -> None:
    # Typed below the servos' starting speed: both lifted by one factor (seed 002 eq. 5.4).
    kept = model.set_velocities({"drive_linear": 0.1, "drive_turn": 0.05})
    assert kept == pytest.approx({"drive_linear": 0.2, "drive_turn": 0.1})
    assert model.velocities() == pytest.approx({"drive_linear": 0.2, "drive_turn": 0.1})
    # Above the maxima: both brought down by one factor (eq. 5.2).
    model.set_velocities({"drive_linear": 0.6, "drive_turn": 0.4})
    v, w = model.velocities()["drive_linear"], model.velocities()["drive_turn"]
    assert v == pytest.approx(model.max_velocity("drive_linear"))
    assert v / w == pytest.approx(0.6 / 0.4)
    # A lower maximum rescales the standing request, ratio kept.
    model.set_max_velocity("drive_linear", 0.25)
    v, w = model.velocities()["drive_linear"], model.velocities()["drive_turn"]
    assert v == pytest.approx(0.25)
    assert v / w == pytest.approx(0.6 / 0.4)


def test_fine_drive_keys_keep_the_ratio_of_their_speeds(model: ConsoleModel) -> None:
    model.set_fine(True)
    model.hotkey_down("W", "drive_linear", 1)
    model.hotkey_down("A", "drive_turn", 1)
    v, w = model.velocities()["drive_linear"], model.velocities()["drive_turn"]
    ratio = model.hotkey_speed("drive_linear") / model.hotkey_speed("drive_turn")
    assert v / w == pytest.approx(ratio)
    model.hotkey_up("A")
    assert model.velocities() == {"drive_linear": pytest.approx(0.2)}  # lifted alone


def test_what_is_sent_feeds_the_prediction(model: ConsoleModel) -> None:
    reading = JointReading("shoulder", 5, 1, 2, 0.1, 0.0, 0.0, 0, 0.1, 0.0, 0.0)
    model.on_telemetry(frame({"shoulder": reading}, model.clock(), 0.0))
    start = model.clock()
    model.set_velocity("shoulder", 0.2)
    predicted = model.predicted_angles(start + 1.0)["shoulder"]
    assert predicted == pytest.approx(0.1 + 0.2 * 1.0, abs=0.02)


def test_a_planner_drives_free_channels_and_the_operator_always_wins(
    model: ConsoleModel,
) -> None:
    model.set_velocity("shoulder", 0.1)  # the operator's
    applied = model.set_external_velocities({"waist": 99.0, "shoulder": 0.3})
    # Bounded like every input; a channel the operator drives stays the operator's.
    assert applied == {"waist": model.limits.get("waist")}
    assert model.channel("waist").source is Source.ROS
    assert model.channel("shoulder") == ChannelCommand(0.1, Source.SLIDER)
    assert model.external_channels == ["waist"]
    with pytest.raises(CommandError, match="unknown velocity channel"):
        model.set_external_velocities({"tail": 0.1})
    with pytest.raises(CommandError):
        model.set_external_velocities({"waist": math.nan})
    # Focus lost (halt keeping the planner): the operator's motion stops, the planner's not.
    model.halt("focus lost", lock="focus lost")
    assert model.velocities() == {"waist": model.limits.get("waist")}
    # Any manual input overrides the planner on every channel at once.
    model.hotkey_down("Y", "shoulder", 1)
    assert model.external_channels == []
    assert "waist" not in model.velocities()
    # The e-stop holds planner velocities at zero until the operator releases it.
    model.hotkey_up("Y")
    model.emergency_stop("test")
    model.set_external_velocities({"waist": 0.2})
    assert model.velocities() == {}
    model.release_estop()
    assert model.velocities() == {"waist": 0.2}
    model.clear_external()
    assert model.velocities() == {}


def test_stream_requests_are_the_models_and_checked(model: ConsoleModel) -> None:
    from ocu.records import CameraRequest

    seen: list[tuple[CameraRequest, ...]] = []
    model.events.stream_request_changed.connect(seen.append)
    wanted = CameraRequest(2, 320, 240, 15)
    model.set_stream_request(wanted)
    assert model.stream_request[2] == wanted
    model.set_stream_request(wanted)  # no change, no event
    assert len(seen) == 1
    with pytest.raises(CommandError, match="camera 7"):
        model.set_stream_request(CameraRequest(7, 320, 240, 15))


def test_the_robot_state_is_the_one_copy_views_read(
    model: ConsoleModel, profile: RobotProfile
) -> None:
    from ocu.protocol.extended import StatusPacket
    from ocu.records import LinkState, StatusFrame

    robot = model.robot
    frames: list[TelemetryFrame] = []
    robot.events.telemetry_changed.connect(frames.append)
    bad = replace(reading(profile, "elbow", 40.0), fault="outside its limits")
    model.on_telemetry(frame({"waist": reading(profile, "waist", 0.5), "elbow": bad}, 10.0))
    assert len(frames) == 1
    assert robot.frame is frames[0]
    assert robot.angles() == {"waist": 0.5}  # an implausible reading is not believed
    assert robot.faults() == {"elbow": "outside its limits"}
    assert robot.fresh_at("waist") == 10.0
    assert robot.telemetry_age(now=12.5) == 2.5
    assert robot.history["waist"][-1][1] == pytest.approx(math.degrees(0.5))
    assert robot.history["elbow"][-1][1] is None  # not plotted at -11796480°
    # History is trimmed to its window.
    model.on_telemetry(frame({"waist": reading(profile, "waist", 0.6)}, 10.0 + robot.history_s + 1))
    assert len(robot.history["waist"]) == 1
    # Link state: CONNECTING forgets the last telemetry's time; the status goes with the
    # extension.
    robot.on_link_state(LinkState.CONNECTING, "reconnect")
    assert robot.last_telemetry_at is None
    robot.on_extension(True, "hello answered")
    status = StatusFrame(StatusPacket(charge_permille=550), 11.0, 0.0)
    robot.on_status(status)
    assert robot.status is status
    robot.on_extension(False, "silent")
    assert robot.status is None


# ---- the game controller (ocu.gamepad drives these; tests/gamepad has the pad's side) ------


def test_gamepad_input_is_checked_before_anything_applies(model: ConsoleModel) -> None:
    model.set_gamepad({"neck": 0.5})
    for bad in ({"neck": math.nan}, {"nek": 0.1}, {"neck": 0.2, "waist": math.inf}):
        with pytest.raises(CommandError):
            model.set_gamepad(bad)
    with pytest.raises(ValueError, match="direction"):
        model.set_gamepad({}, {"flippers": 2})
    assert model.velocities() == {"neck": 0.5 * model.max_velocity("neck")}
    model.set_gamepad({"neck": 3.0})  # a share beyond full is full
    assert model.velocities() == {"neck": model.max_velocity("neck")}


def test_halt_keeps_the_pad_only_when_asked_and_the_pad_waits_for_rest(
    model: ConsoleModel,
) -> None:
    model.set_gamepad({"neck": 0.5}, {"flippers": 1})
    model.hotkey_down("W", "drive_linear", 1)
    assert model.halt("console lost focus", lock="focus lost", pad_background=True)
    assert set(model.velocities()) == {"neck", "flippers"}
    assert model.velocities()["flippers"] == model.hotkey_speed("flippers")
    model.halt("window hidden")
    assert model.velocities() == {}
    model.set_gamepad({"neck": 0.6}, {"flippers": 1})  # still deflected: nothing resumes
    assert model.velocities() == {}
    model.set_gamepad({"neck": 0.0}, {"flippers": 1})
    model.set_gamepad({"neck": 0.4}, {"flippers": 1})
    assert set(model.velocities()) == {"neck"}
    assert model.stop_gamepad("deadman released")
    assert model.velocities() == {}
    assert model.gamepad_channels == []
