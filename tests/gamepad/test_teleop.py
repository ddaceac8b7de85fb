"""The pad on the console model, without Qt or SDL: deadman, arming, the latest input wins.

Pad states are built by hand here; tests/windows/test_gamepad.py drives the same logic
through SDL's virtual pad, the real console and the real simulator.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import pytest

from ocu.console.model import ConsoleModel, Source
from ocu.gamepad.calibration import AxisCalibration, PadCalibration
from ocu.gamepad.mapping import PadMapping, load_pad_mapping, parse_pad_mapping
from ocu.gamepad.pad import AXES, BUTTONS, PadInfo, PadState
from ocu.gamepad.teleop import GamepadTeleop, PadStatus, Stopper
from ocu.profile import RobotProfile

FULL = 32767  # a stick right or down, a trigger pressed
UP = -32768  # a stick up or left
PAD = PadInfo(name="test pad", guid="guid-1", instance_id=7)


class Pad:
    """A hand-held pad: what is held now, fed to the teleop as one poll."""

    def __init__(self, teleop: GamepadTeleop, info: PadInfo = PAD) -> None:
        self.teleop = teleop
        self.info = info
        self.axes: dict[str, int] = dict.fromkeys(AXES, 0)
        self.down: set[str] = set()

    def plug(self) -> None:
        self.teleop.on_connected(self.info)
        self.poll()

    def poll(self, pressed: frozenset[str] = frozenset()) -> None:
        state = PadState(
            instance_id=self.info.instance_id,
            axes=tuple(self.axes[a] for a in AXES),
            buttons=tuple(b in self.down for b in BUTTONS),
            polled_at=0.0,
            pressed=pressed,
        )
        self.teleop.on_state(state)

    def set(self, axes: Mapping[str, int] | None = None, **buttons: bool) -> None:
        self.axes.update(axes or {})
        for button, down in buttons.items():
            (self.down.add if down else self.down.discard)(button)
        self.poll()


@pytest.fixture
def model(profile: RobotProfile) -> ConsoleModel:
    return ConsoleModel(profile)


@pytest.fixture
def mapping(profile: RobotProfile) -> PadMapping:
    return load_pad_mapping(profile)


@pytest.fixture
def teleop(model: ConsoleModel, mapping: PadMapping) -> GamepadTeleop:
    teleop = GamepadTeleop(model, mapping)
    teleop.start()
    return teleop


@pytest.fixture
def pad(teleop: GamepadTeleop) -> Pad:
    pad = Pad(teleop)
    pad.plug()
    return pad


def velocity(model: ConsoleModel, channel: str) -> float:
    return model.channel(channel).velocity


def test_stick_moves_only_while_the_deadman_is_held(model: ConsoleModel, pad: Pad) -> None:
    pad.set(leftshoulder=True)
    assert pad.teleop.engaged
    pad.set({"lefty": UP})
    assert velocity(model, "drive_linear") == pytest.approx(model.max_velocity("drive_linear"))
    assert model.channel("drive_linear").source is Source.GAMEPAD
    pad.set(leftshoulder=False)
    assert model.velocities() == {}
    assert pad.teleop.status is PadStatus.READY
    # Pressing the deadman again with the stick still forward starts nothing...
    pad.set(leftshoulder=True)
    assert model.velocities() == {}
    # ...until the stick has been back at rest.
    pad.set({"lefty": 0})
    pad.set({"lefty": UP // 2})
    assert 0 < velocity(model, "drive_linear") < model.max_velocity("drive_linear")


def test_without_the_deadman_nothing_moves(model: ConsoleModel, pad: Pad) -> None:
    pad.set({"lefty": UP, "righty": UP, "lefttrigger": FULL}, dpup=True)
    assert model.velocities() == {}


def test_pad_plugged_in_with_everything_held_starts_nothing(
    model: ConsoleModel, teleop: GamepadTeleop
) -> None:
    pad = Pad(teleop)
    pad.axes["lefty"] = UP
    pad.down |= {"leftshoulder", "dpup"}
    pad.plug()
    pad.poll()
    assert model.velocities() == {}
    assert teleop.status is PadStatus.READY
    pad.set(leftshoulder=False)
    pad.set(leftshoulder=True)  # a fresh deadman press: stick and D-pad still held
    assert model.velocities() == {}
    pad.set(dpup=False)
    pad.set(dpup=True)
    assert velocity(model, "flippers") == model.hotkey_speed("flippers")
    assert velocity(model, "drive_linear") == 0.0


def test_sticks_are_bounded_by_the_console_maximum_and_shaped(
    model: ConsoleModel, pad: Pad
) -> None:
    model.set_max_velocity("shoulder", 0.2)
    pad.set(leftshoulder=True)
    pad.set({"righty": UP})
    assert velocity(model, "shoulder") == pytest.approx(0.2)
    model.set_max_velocity("shoulder", 0.1)  # lowering the maximum slows the stick at once
    assert velocity(model, "shoulder") == pytest.approx(0.1)
    pad.set({"righty": UP // 2})
    expected = pad.teleop.mapping.shape("righty").apply(0.5) * 0.1
    assert velocity(model, "shoulder") == pytest.approx(expected, rel=1e-3)
    pad.set({"righty": -1000})  # inside the deadzone
    assert velocity(model, "shoulder") == 0.0


def test_drive_pair_keeps_the_turn_radius(model: ConsoleModel, pad: Pad) -> None:
    pad.set(leftshoulder=True)
    pad.set({"lefty": UP, "leftx": FULL})
    linear, turn = velocity(model, "drive_linear"), velocity(model, "drive_turn")
    assert linear > 0 > turn  # forward and right
    limits = model.max_velocity("drive_linear"), model.max_velocity("drive_turn")
    assert abs(linear) <= limits[0] + 1e-9
    assert abs(turn) <= limits[1] + 1e-9


def test_alt_button_switches_the_right_stick_and_disarms_it(model: ConsoleModel, pad: Pad) -> None:
    pad.set(leftshoulder=True)
    pad.set({"righty": UP})
    assert velocity(model, "shoulder") > 0
    pad.set(rightshoulder=True)  # the stick now means the neck: it must come back to rest
    assert velocity(model, "shoulder") == 0.0
    assert velocity(model, "neck") == 0.0
    pad.set({"righty": 0})
    pad.set({"righty": UP})
    assert velocity(model, "neck") > 0
    assert velocity(model, "shoulder") == 0.0


def test_triggers_open_and_close_the_gripper(model: ConsoleModel, pad: Pad) -> None:
    pad.set(leftshoulder=True)
    pad.set({"lefttrigger": FULL})
    assert velocity(model, "gripper") == pytest.approx(model.max_velocity("gripper"))
    pad.set({"lefttrigger": 0, "righttrigger": FULL})
    assert velocity(model, "gripper") == pytest.approx(-model.max_velocity("gripper"))


def test_estop_button_latches_like_space_and_needs_a_fresh_deadman(
    model: ConsoleModel, pad: Pad
) -> None:
    pad.set(leftshoulder=True)
    pad.set({"lefty": UP})
    pad.set(b=True)
    assert model.estopped
    assert model.estop_reason == "gamepad"
    assert model.velocities() == {}
    assert pad.teleop.status is PadStatus.READY
    pad.set({"lefty": 0}, b=False)
    pad.set({"lefty": UP})  # the deadman is still held, but was not pressed anew
    assert model.estopped
    pad.set({"lefty": 0}, leftshoulder=False)
    pad.set(leftshoulder=True)
    pad.set({"lefty": UP})  # acting again releases the latch, like a key press
    assert not model.estopped
    assert velocity(model, "drive_linear") > 0


def test_estop_tap_between_two_takes_still_stops(model: ConsoleModel, pad: Pad) -> None:
    pad.set(leftshoulder=True)
    pad.set({"lefty": UP})
    pad.poll(pressed=frozenset({"b"}))  # pressed and released between two polls taken
    assert model.estopped
    assert model.velocities() == {}


def test_estop_button_works_without_the_deadman_and_when_inactive(
    model: ConsoleModel, pad: Pad
) -> None:
    pad.teleop.set_active(False, "console hidden")
    pad.set(b=True)
    assert model.estopped


def test_space_and_stop_all_disengage_the_pad(model: ConsoleModel, pad: Pad) -> None:
    pad.set(leftshoulder=True)
    pad.set({"lefty": UP})
    model.emergency_stop("Space")
    assert model.velocities() == {}
    assert not pad.teleop.engaged
    pad.set({"lefty": UP + 100})
    assert model.velocities() == {}


def test_latest_manual_input_wins_and_the_pad_waits_for_rest(model: ConsoleModel, pad: Pad) -> None:
    pad.set(leftshoulder=True)
    pad.set({"righty": UP})
    model.set_velocity("shoulder", -0.1)  # a slider takes the channel
    assert model.channel("shoulder").source is Source.SLIDER
    pad.set({"righty": UP + 3000})  # the stick still deflected: the slider keeps it
    assert velocity(model, "shoulder") == -0.1
    pad.set({"righty": 0})  # the stick at rest does not stop the slider...
    assert velocity(model, "shoulder") == -0.1
    pad.set({"righty": UP})  # ...a new deflection takes the channel back
    assert model.channel("shoulder").source is Source.GAMEPAD
    model.hotkey_down("Y", "shoulder", -1)  # so does a key
    assert model.channel("shoulder").source is Source.HOTKEY


def test_pad_takes_a_joint_from_the_position_controller_and_ros(
    model: ConsoleModel, pad: Pad
) -> None:
    model.set_target("shoulder", 0.5)
    model.set_external_velocities({"drive_linear": 0.25})
    pad.set(leftshoulder=True)
    pad.set({"righty": UP})
    assert "shoulder" not in model.targets
    assert model.external_channels == []  # any operator input wins over ROS
    assert model.set_external_velocities({"shoulder": 0.3}) == {}


def test_unplug_error_stall_and_focus_stop_the_pad(model: ConsoleModel, pad: Pad) -> None:
    teleop = pad.teleop
    stops: list[tuple[Callable[[], None], PadStatus]] = [
        (lambda: teleop.on_disconnected("unplugged"), PadStatus.NO_PAD),
        (lambda: teleop.on_error("SDL_GameControllerGetAxis failed"), PadStatus.ERROR),
        (lambda: teleop.on_stalled("poll thread silent"), PadStatus.STALLED),
        (lambda: teleop.set_active(False, "console hidden"), PadStatus.INACTIVE),
    ]
    for stop, status in stops:
        if teleop.info is None:
            pad.plug()
        teleop.on_polling()
        teleop.set_active(True)
        pad.set({"lefty": 0}, leftshoulder=False)
        pad.set(leftshoulder=True)
        pad.set({"lefty": UP})
        assert velocity(model, "drive_linear") > 0
        stop()
        assert model.velocities() == {}, status
        assert teleop.status is status
        pad.poll()  # the deadman still held and the stick forward: nothing resumes
        assert model.velocities() == {}, status


def test_other_inputs_survive_the_pad_letting_go(model: ConsoleModel, pad: Pad) -> None:
    model.set_velocity("neck", 0.2)
    pad.set(leftshoulder=True)
    pad.set({"lefty": UP})
    pad.set(leftshoulder=False)
    assert model.velocities() == {"neck": 0.2}


def test_buttons_give_commands(model: ConsoleModel, pad: Pad) -> None:
    pad.set(y=True)
    assert model.torch
    pad.set(y=False)
    pad.set(x=True)
    assert model.camera == 0
    pad.set(x=False)
    pad.set(x=True)
    assert model.camera == 1
    pad.set(back=True)
    assert model.camera == 0
    pad.set(start=True)
    assert model.help_visible


def test_pose_hook_needs_the_deadman_and_stops_with_it(
    model: ConsoleModel, mapping: PadMapping, profile: RobotProfile
) -> None:
    mapping = parse_pad_mapping({"buttons": {"a": "pose stow"}}, profile, mapping, "test")
    teleop = GamepadTeleop(model, mapping)
    messages: list[str] = []
    teleop.events.message.connect(messages.append)
    pad = Pad(teleop)
    pad.plug()
    pad.set(a=True)
    assert "no pose hook" in messages[-1]
    poses: list[str] = []

    def go_to_pose(name: str) -> Stopper:
        poses.append(name)
        targets = {"shoulder": 0.4, "elbow": -0.3}
        model.set_targets(targets)

        def stop(_reason: str) -> None:  # the pose's own targets, not the operator's
            for joint in targets:
                model.cancel_targets(joint)

        return stop

    teleop.register_hook("pose", go_to_pose)
    pad.set(a=False)
    pad.set(a=True)
    assert poses == []
    assert "hold the deadman" in messages[-1]
    pad.set(a=False, leftshoulder=True)
    model.set_target("waist", 0.1)  # the operator's own target: the pad must not cancel it
    pad.set(a=True)
    assert poses == ["stow"]
    assert set(model.targets) == {"shoulder", "elbow", "waist"}
    pad.set(leftshoulder=False)
    assert set(model.targets) == {"waist"}


def test_a_hook_move_stops_when_the_deadman_is_released(
    model: ConsoleModel, mapping: PadMapping, profile: RobotProfile
) -> None:
    """A hook that returns a stopper (the console's arm move) is stopped on letting go."""
    mapping = parse_pad_mapping({"buttons": {"a": "pose ready"}}, profile, mapping, "test")
    teleop = GamepadTeleop(model, mapping)
    stops: list[str] = []
    teleop.register_hook("pose", lambda name: stops.append)
    pad = Pad(teleop)
    pad.plug()
    pad.set(leftshoulder=True)
    pad.set(a=True)
    assert stops == []
    pad.set(leftshoulder=False)
    assert len(stops) == 1
    pad.set(leftshoulder=True)
    pad.set(leftshoulder=False)
    assert len(stops) == 1  # stopped once, not again


def test_no_deadman_mapping_engages_with_sticks_armed(
    model: ConsoleModel, mapping: PadMapping, profile: RobotProfile
) -> None:
    mapping = parse_pad_mapping({"options": {"deadman": ""}}, profile, mapping, "test")
    teleop = GamepadTeleop(model, mapping)
    pad = Pad(teleop)
    pad.axes["lefty"] = UP
    pad.plug()
    pad.poll()
    assert teleop.engaged
    assert model.velocities() == {}  # plugged in mid-motion: the stick must come back first
    pad.set({"lefty": 0})
    pad.set({"lefty": UP})
    assert velocity(model, "drive_linear") > 0


def test_turbo_and_scale(model: ConsoleModel, mapping: PadMapping, profile: RobotProfile) -> None:
    options = {"scale": 0.5, "turbo_button": "a"}
    teleop = GamepadTeleop(model, parse_pad_mapping({"options": options}, profile, mapping))
    pad = Pad(teleop)
    pad.plug()
    pad.set(leftshoulder=True)
    pad.set({"righty": UP})
    assert velocity(model, "shoulder") == pytest.approx(0.5 * model.max_velocity("shoulder"))
    pad.set(a=True)
    assert velocity(model, "shoulder") == pytest.approx(model.max_velocity("shoulder"))


def test_calibration_centres_a_worn_stick(model: ConsoleModel, pad: Pad) -> None:
    pad.teleop.set_calibration(PadCalibration({"righty": AxisCalibration(-28000, 6000, 28000)}))
    pad.set({"righty": 6000}, leftshoulder=True)  # a worn stick at rest reads 6000
    assert model.velocities() == {}
    pad.set({"righty": -28000})
    assert velocity(model, "shoulder") == pytest.approx(model.max_velocity("shoulder"))


def test_states_of_another_pad_are_ignored(model: ConsoleModel, pad: Pad) -> None:
    other = Pad(pad.teleop, PadInfo(name="old", guid="g", instance_id=99))
    pad.set(leftshoulder=True)
    other.set({"lefty": UP}, leftshoulder=True)
    assert model.velocities() == {}
