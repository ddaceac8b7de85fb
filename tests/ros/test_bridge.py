"""The ROS-free bridge core: the 0.2 rule, cmd_vel timeout, joint goals, override, reports."""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from ocu.control.commands import VelocityLimits
from ocu.control.position import PositionError
from ocu.kinematics.arm import ArmError, ToolPose
from ocu.profile import RobotProfile, load_profile
from ocu.records import JointReading, LinkState, LinkStats
from ocu.ros.bridge import BridgeCore
from ocu.ros.convert import (
    BridgeError,
    BridgeSettings,
    CmdVelTimeout,
    bound_arm_twist,
    camera_name,
    joint_state,
    quaternion_xyzw,
    quoted,
    rotation_of,
    twist_to_drive,
)
from ocu.ros.diagnostics import BridgeState, DiagnosticLevel, LinkGate, bridge_report, link_report

# The Engineer's chassis channels, by their roles in the shipped profile.
DRIVE_LINEAR, DRIVE_TURN = load_profile().drive_channels or ("", "")


class Clock:
    """A hand-driven monotonic clock."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


class Sink:
    """Records every set_velocities call."""

    def __init__(self) -> None:
        self.sent: list[dict[str, float]] = []
        self.current: dict[str, float] = {}

    def set_velocities(self, **velocities: float) -> None:
        self.sent.append(velocities)
        self.current.update(velocities)


def state_of(core: BridgeCore) -> BridgeState:
    """The state, read through a call so mypy does not narrow it between asserts."""
    return core.state


def gate_of(core: BridgeCore) -> LinkGate:
    """The link gate, read through a call for the same reason."""
    return core.link_gate


def reading(name: str, angle_rad: float | None) -> JointReading:
    return JointReading(name, 0, 1, 2, angle_rad, 0.5, 1.25, 0, angle_rad, 0.0, 0.0)


@pytest.fixture
def clock() -> Clock:
    return Clock()


@pytest.fixture
def states() -> list[tuple[BridgeState, str]]:
    return []


@pytest.fixture
def core(profile: RobotProfile, clock: Clock, states: list[tuple[BridgeState, str]]) -> BridgeCore:
    return BridgeCore(
        profile, clock=clock, on_state_changed=lambda state, text: states.append((state, text))
    )


@pytest.fixture
def sink(core: BridgeCore) -> Sink:
    sink = Sink()
    core.attach(sink)
    return sink


# ---- drive scaling: the 0.2 rule with the turn radius kept ------------------------------


def test_twist_mapping_lifts_then_clamps_to_the_channel_maximum(profile: RobotProfile) -> None:
    limits = VelocityLimits(profile)
    settings = BridgeSettings.from_profile(profile)
    assert twist_to_drive(0.1, -0.1, settings, limits) == {DRIVE_LINEAR: 0.2, DRIVE_TURN: -0.2}
    default_max = profile.channels[DRIVE_LINEAR].default_max
    assert twist_to_drive(0.5, 0.0, settings, limits)[DRIVE_LINEAR] == default_max
    limits.set(DRIVE_LINEAR, 0.45)
    assert twist_to_drive(0.45, 0.0, settings, limits)[DRIVE_LINEAR] == 0.45
    limits.set(DRIVE_LINEAR, 0.1)  # a maximum below the minimum wins: never faster than it
    assert twist_to_drive(0.05, 0.0, settings, limits)[DRIVE_LINEAR] == 0.1


@pytest.mark.parametrize(
    ("twist", "expected"),
    [
        ((0.1, 0.05), (0.2, 0.1)),  # lifted by one factor: the 2 m arc stays a 2 m arc
        ((0.1, -0.05), (0.2, -0.1)),
        ((-0.05, 0.1), (-0.1, 0.2)),
        ((0.6, 0.4), (0.3, 0.2)),  # clamped by one factor: linear at its maximum 0.3
        ((0.15, 1.6), (0.075, 0.8)),  # turn at its maximum 0.8
        ((0.25, 0.5), (0.25, 0.5)),  # within the bounds: unchanged
    ],
)
def test_twist_mapping_keeps_the_turn_radius(
    profile: RobotProfile, twist: tuple[float, float], expected: tuple[float, float]
) -> None:
    drive = twist_to_drive(*twist, BridgeSettings.from_profile(profile), VelocityLimits(profile))
    assert (drive[DRIVE_LINEAR], drive[DRIVE_TURN]) == pytest.approx(expected)
    assert drive[DRIVE_LINEAR] / drive[DRIVE_TURN] == pytest.approx(twist[0] / twist[1])


def test_maxima_are_the_links_current_limits(profile: RobotProfile) -> None:
    limits = VelocityLimits(profile)
    limits.set(DRIVE_TURN, 0.4)  # the operator lowered the turn maximum at run time
    drive = twist_to_drive(0.2, 0.8, BridgeSettings.from_profile(profile), limits)
    assert drive == pytest.approx({DRIVE_LINEAR: 0.1, DRIVE_TURN: 0.4})


@pytest.mark.parametrize("tiny", [1e-300, -1e-300, 5e-324, 9.9e-4])
def test_speeds_below_epsilon_are_zero_before_the_minimum_rule(
    profile: RobotProfile, tiny: float
) -> None:
    settings, limits = BridgeSettings.from_profile(profile), VelocityLimits(profile)
    assert twist_to_drive(tiny, 0.0, settings, limits) == {DRIVE_LINEAR: 0.0, DRIVE_TURN: 0.0}
    assert twist_to_drive(0.0, tiny, settings, limits) == {DRIVE_LINEAR: 0.0, DRIVE_TURN: 0.0}
    assert twist_to_drive(tiny, 0.1, settings, limits) == {DRIVE_LINEAR: 0.0, DRIVE_TURN: 0.2}


finite = st.floats(allow_nan=False, allow_infinity=False, min_value=-1e6, max_value=1e6)


@given(linear=finite, angular=finite)
def test_twist_mapping_keeps_signs_and_bounds(
    profile: RobotProfile, linear: float, angular: float
) -> None:
    drive = twist_to_drive(
        linear, angular, BridgeSettings.from_profile(profile), VelocityLimits(profile)
    )
    for requested, sent, channel in (
        (linear, drive[DRIVE_LINEAR], DRIVE_LINEAR),
        (angular, drive[DRIVE_TURN], DRIVE_TURN),
    ):
        assert abs(sent) <= profile.channels[channel].default_max + 1e-12
        if sent != 0.0:
            assert math.copysign(1.0, sent) == math.copysign(1.0, requested)


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_twist_mapping_refuses_non_finite_speeds(profile: RobotProfile, value: float) -> None:
    settings, limits = BridgeSettings.from_profile(profile), VelocityLimits(profile)
    with pytest.raises(BridgeError, match="finite"):
        twist_to_drive(value, 0.0, settings, limits)
    with pytest.raises(BridgeError, match="finite"):
        twist_to_drive(0.1, value, settings, limits)


def test_thresholds_default_to_the_profile_and_are_parameters(profile: RobotProfile) -> None:
    settings = BridgeSettings.from_profile(profile)
    assert settings.min_linear_m_s == profile.channels[DRIVE_LINEAR].min_speed == 0.2
    assert settings.min_angular_rad_s == profile.channels[DRIVE_TURN].min_speed == 0.2
    custom = BridgeSettings.from_profile(profile, min_linear_m_s=0.05)
    assert twist_to_drive(0.1, 0.0, custom, VelocityLimits(profile))[DRIVE_LINEAR] == 0.1


@pytest.mark.parametrize(
    ("field", "value", "match"),
    [
        ("min_linear_m_s", -0.1, "min_linear_m_s"),
        ("min_angular_rad_s", math.nan, "min_angular_rad_s"),
        ("cmd_vel_timeout_s", 0.0, "cmd_vel_timeout_s"),
        ("cmd_vel_timeout_s", 86400.0, "cmd_vel_timeout_s must be > 0 and at most 2 s"),
        ("cmd_vel_timeout_s", math.inf, "cmd_vel_timeout_s"),
        ("rate_hz", 1.0, "rate_hz"),
    ],
)
def test_bad_settings_are_refused(
    profile: RobotProfile, field: str, value: float, match: str
) -> None:
    with pytest.raises(BridgeError, match=match):
        BridgeSettings.from_profile(profile, **{field: value})


# ---- cmd_vel timeout --------------------------------------------------------------------


def test_timeout_fires_once_per_silence() -> None:
    timeout = CmdVelTimeout(0.5)
    assert not timeout.expired(10.0)  # nothing received yet
    assert timeout.age(10.0) is None
    timeout.feed(10.0)
    assert not timeout.expired(10.5)
    assert timeout.expired(10.51)
    assert not timeout.expired(11.0)
    timeout.feed(11.0)
    assert timeout.age(11.25) == 0.25
    assert timeout.expired(11.6)


def test_core_stops_the_tracks_once_when_cmd_vel_stops(
    core: BridgeCore, sink: Sink, clock: Clock, caplog: pytest.LogCaptureFixture
) -> None:
    assert core.on_cmd_vel(0.1, 0.0) == {DRIVE_LINEAR: 0.2, DRIVE_TURN: 0.0}
    assert sink.current[DRIVE_LINEAR] == 0.2
    assert state_of(core) is BridgeState.COMMANDING
    clock.now += 0.49
    core.step()
    assert sink.current[DRIVE_LINEAR] == 0.2
    caplog.set_level(logging.WARNING, logger="ocu.ros")
    clock.now += 0.02
    core.step()
    assert sink.sent[-1] == {DRIVE_LINEAR: 0.0, DRIVE_TURN: 0.0}
    assert state_of(core) is BridgeState.LISTENING
    sends = len(sink.sent)
    clock.now += 1.0
    core.step()
    assert len(sink.sent) == sends
    assert [r.message for r in caplog.records] == ["no cmd_vel for 0.50 s: tracks stopped"]
    assert core.status().timeouts == 1


def test_zero_cmd_vel_stops_and_non_finite_stops_too(core: BridgeCore, sink: Sink) -> None:
    core.on_cmd_vel(0.3, 0.5)
    assert state_of(core) is BridgeState.COMMANDING
    core.on_cmd_vel(0.0, 0.0)
    assert sink.current == {DRIVE_LINEAR: 0.0, DRIVE_TURN: 0.0}
    assert state_of(core) is BridgeState.LISTENING
    core.on_cmd_vel(0.3, 0.0)
    with pytest.raises(BridgeError):
        core.on_cmd_vel(math.nan, 0.0)
    assert sink.current == {DRIVE_LINEAR: 0.0, DRIVE_TURN: 0.0}


def test_other_twist_components_are_ignored_with_one_warning(
    core: BridgeCore, sink: Sink, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, logger="ocu.ros")
    for _ in range(3):
        assert core.on_cmd_vel(0.25, 0.0, (0.3, 0.0, 0.0, 0.1)) == {
            DRIVE_LINEAR: 0.25,
            DRIVE_TURN: 0.0,
        }
    assert len(caplog.records) == 1
    assert "ignored" in caplog.records[0].message


def test_nothing_is_sent_before_attach(core: BridgeCore) -> None:
    assert core.on_cmd_vel(0.3, 0.0) is None
    assert core.step() == []
    with pytest.raises(PositionError, match="not in control"):
        core.set_goals(["waist"], [0.1])


# ---- override (the console) -------------------------------------------------------------


def test_override_silences_ros_at_once_and_sends_nothing(
    core: BridgeCore, sink: Sink, clock: Clock, states: list[tuple[BridgeState, str]]
) -> None:
    core.on_cmd_vel(0.3, 0.0)
    sends = len(sink.sent)
    assert core.override("Space") is True
    assert state_of(core) is BridgeState.OVERRIDDEN
    assert len(sink.sent) == sends  # the console's own command replaces ROS's
    assert core.on_cmd_vel(0.4, 0.0) is None
    clock.now += 5.0
    core.step()
    assert len(sink.sent) == sends
    assert core.override() is False  # already overridden
    core.enable()
    assert state_of(core) is BridgeState.LISTENING
    assert core.on_cmd_vel(0.1, 0.0) == {DRIVE_LINEAR: 0.2, DRIVE_TURN: 0.0}
    assert [s for s, _ in states] == [
        BridgeState.LISTENING,
        BridgeState.COMMANDING,
        BridgeState.OVERRIDDEN,
        BridgeState.LISTENING,
        BridgeState.COMMANDING,
    ]
    assert states[2][1] == "ROS control overridden by the operator"


def test_override_cancels_joint_goals(core: BridgeCore, sink: Sink) -> None:
    core.on_telemetry({"waist": reading("waist", 0.0)}, core.clock())
    core.set_goals(["waist"], [0.5])
    core.step()
    core.override()
    assert core.status().goals_rad == {}
    core.enable()
    assert core.status().goals_rad == {}


def test_detach_zeroes_only_what_ros_was_moving(core: BridgeCore, sink: Sink) -> None:
    core.on_cmd_vel(0.0, 0.5)
    core.on_telemetry({"elbow": reading("elbow", 0.0)}, core.clock())
    core.set_goals(["elbow"], [0.4])
    core.step()
    core.detach()
    assert sink.sent[-1] == {DRIVE_TURN: 0.0, "elbow": 0.0}
    assert state_of(core) is BridgeState.OFF
    sends = len(sink.sent)
    assert core.on_cmd_vel(0.3, 0.0) is None
    assert len(sink.sent) == sends


def test_detach_without_motion_sends_nothing(core: BridgeCore, sink: Sink) -> None:
    core.detach()
    assert sink.sent == []


# ---- link loss: zeros while LOST, no resuming by itself after it -------------------------


def stream(
    core: BridgeCore, clock: Clock, duration_s: float, twist: tuple[float, float]
) -> list[dict[str, float] | None]:
    """A planner publishing `twist` at 20 Hz for `duration_s`; what on_cmd_vel returned."""
    results: list[dict[str, float] | None] = []
    for _ in range(round(duration_s / 0.05)):
        clock.now += 0.05
        results.append(core.on_cmd_vel(*twist))
        core.step()
    return results


def test_link_lost_zeroes_ros_motion_and_refuses_cmd_vel(
    core: BridgeCore, sink: Sink, clock: Clock, caplog: pytest.LogCaptureFixture
) -> None:
    core.on_telemetry({"elbow": reading("elbow", 0.0)}, clock.now)
    core.set_goals(["elbow"], [0.4])
    core.on_cmd_vel(0.3, 0.2)
    core.step()
    assert sink.current["elbow"] > 0.0
    caplog.set_level(logging.WARNING, logger="ocu.ros")
    core.on_link_state(LinkState.LOST, "no valid packet from the robot for 3.0 s")
    lost_at = len(sink.sent) - 1
    assert sink.sent[-1] == {DRIVE_LINEAR: 0.0, DRIVE_TURN: 0.0, "elbow": 0.0}
    assert core.status().goals_rad == {}
    assert state_of(core) is BridgeState.LISTENING
    assert gate_of(core) is LinkGate.LOST
    assert "LINK LOST" in caplog.records[-1].message
    assert "ROS commands refused" in caplog.records[-1].message

    assert all(result is None for result in stream(core, clock, 2.0, (0.3, 0.2)))
    assert all(not any(sent.values()) for sent in sink.sent[lost_at:])  # only zeros since
    status = core.status()
    assert status.link_refused_count == 40
    assert status.drive == {DRIVE_LINEAR: 0.0, DRIVE_TURN: 0.0}
    assert core.refusal() == "LINK LOST: cmd_vel refused, zeros sent"
    with pytest.raises(PositionError, match="LINK LOST"):
        core.set_goals(["elbow"], [0.4])
    assert core.set_goals([], []) == {}  # cancelling is always allowed
    report = bridge_report(core.status(), "sim")
    assert report.level is DiagnosticLevel.ERROR
    assert "LINK LOST" in report.message
    assert dict(report.values)["link gate"] == "link lost"
    assert dict(report.values)["cmd_vel refused (link)"] == "40"


def test_recovery_waits_until_cmd_vel_was_zero_or_silent_for_the_timeout(
    core: BridgeCore, sink: Sink, clock: Clock
) -> None:
    core.on_cmd_vel(0.3, 0.0)
    core.on_link_state(LinkState.LOST)
    stream(core, clock, 1.0, (0.3, 0.0))
    sends = len(sink.sent)
    core.on_link_state(LinkState.CONNECTED, "packets from 127.0.0.1:10000")
    assert gate_of(core) is LinkGate.RECOVERING
    # The planner still streams its old command: recovery must not resume it.
    assert all(result is None for result in stream(core, clock, 3.0, (0.3, 0.0)))
    assert all(not any(sent.values()) for sent in sink.sent[sends:])
    assert bridge_report(core.status(), "sim").level is DiagnosticLevel.WARN
    assert "zero or silent for 0.50 s" in core.refusal()
    # Silent for less than the timeout: still refused, and the silence starts over.
    clock.now += 0.45
    core.step()
    assert core.on_cmd_vel(0.3, 0.0) is None
    clock.now += 0.45
    core.step()
    assert gate_of(core) is LinkGate.RECOVERING
    # Zeros count as quiet: 0.5 s of them, then a new command drives.
    stream(core, clock, 0.1, (0.0, 0.0))
    assert gate_of(core) is LinkGate.OPEN
    assert core.on_cmd_vel(0.25, 0.0) == {DRIVE_LINEAR: 0.25, DRIVE_TURN: 0.0}
    assert sink.current[DRIVE_LINEAR] == 0.25


def test_a_quiet_planner_drives_at_once_after_recovery(
    core: BridgeCore, sink: Sink, clock: Clock
) -> None:
    core.on_cmd_vel(0.3, 0.0)
    core.on_link_state(LinkState.LOST)
    clock.now += 0.6  # the planner stopped publishing before the link came back
    core.on_link_state(LinkState.CONNECTED)
    assert gate_of(core) is LinkGate.OPEN
    assert core.on_cmd_vel(0.25, 0.0) == {DRIVE_LINEAR: 0.25, DRIVE_TURN: 0.0}


def test_a_non_zero_cmd_vel_after_silence_drives_and_is_not_refused(
    core: BridgeCore, sink: Sink, clock: Clock
) -> None:
    core.on_link_state(LinkState.LOST)
    stream(core, clock, 0.5, (0.3, 0.0))
    core.on_link_state(LinkState.CONNECTED)
    clock.now += 0.51
    # The first cmd_vel after the quiet spell opens the gate itself (before step() runs).
    assert core.on_cmd_vel(0.3, 0.0) == {DRIVE_LINEAR: 0.3, DRIVE_TURN: 0.0}


def test_link_state_while_overridden_or_before_attach(
    profile: RobotProfile, core: BridgeCore, sink: Sink, clock: Clock
) -> None:
    core.on_cmd_vel(0.3, 0.0)
    core.override("W")
    sends = len(sink.sent)
    core.on_link_state(LinkState.LOST)
    assert len(sink.sent) == sends  # the operator owns the robot: the bridge sends nothing
    core.enable()
    assert core.on_cmd_vel(0.3, 0.0) is None
    assert core.status().link_refused_count == 1

    # A bridge started on a link that is already lost (the console's toggle) learns it.
    late = BridgeCore(profile, clock=clock)
    late.attach(Sink(), link_state=lambda: LinkState.LOST)
    assert gate_of(late) is LinkGate.LOST
    assert late.on_cmd_vel(0.3, 0.0) is None
    # Reported before attach (the node's tee runs before the bridge starts).
    early = BridgeCore(profile, clock=clock)
    early.on_link_state(LinkState.LOST)
    early.attach(Sink())
    assert early.on_cmd_vel(0.3, 0.0) is None


def test_link_closed_counts_as_lost(core: BridgeCore, sink: Sink) -> None:
    core.on_cmd_vel(0.3, 0.0)
    core.on_link_state(LinkState.CLOSED, "shut down")
    assert sink.current == {DRIVE_LINEAR: 0.0, DRIVE_TURN: 0.0}
    assert core.on_cmd_vel(0.3, 0.0) is None


# ---- joint goals ------------------------------------------------------------------------


def test_joint_goal_runs_through_the_position_controller(
    core: BridgeCore, sink: Sink, clock: Clock
) -> None:
    core.on_telemetry({"waist": reading("waist", 0.0)}, clock.now)
    assert core.set_goals(["waist"], [0.5]) == {"waist": 0.5}
    assert state_of(core) is BridgeState.COMMANDING
    core.step()
    assert sink.current["waist"] > 0.0
    clock.now += 0.1
    core.on_telemetry({"waist": reading("waist", 0.5)}, clock.now)
    # Predicted at the target: the joint stops, but the reading was taken while it moved.
    assert core.step() == []
    assert sink.current["waist"] == 0.0
    clock.now += 0.1
    core.on_telemetry({"waist": reading("waist", 0.5)}, clock.now)
    messages = core.step()
    assert messages == ["waist: reached 28.6°"]  # a reading taken after the stop confirms
    assert sink.current["waist"] == 0.0
    assert state_of(core) is BridgeState.LISTENING


@pytest.mark.parametrize(
    ("names", "positions", "match"),
    [
        (["nonsense"], [0.1], "nonsense: not a joint driven by a velocity channel"),
        (["waist"], [math.radians(175.0)], r"waist: target 175.0° outside the limits"),
        (["waist", "elbow"], [0.1], "2 names but 1 positions"),
        (["waist", "waist"], [0.1, 0.2], "named twice"),
        (["waist"], [math.nan], "finite"),
        (["left_track"], [0.0], "not a joint driven"),
    ],
)
def test_bad_joint_goals_are_refused_whole(
    core: BridgeCore, sink: Sink, names: list[str], positions: list[float], match: str
) -> None:
    core.set_goals(["elbow"], [0.2])
    with pytest.raises(PositionError, match=match):
        core.set_goals(names, positions)
    assert core.status().goals_rad == {"elbow": 0.2}
    assert core.status().rejected_count == 1


def test_one_bad_joint_applies_no_goal(core: BridgeCore, sink: Sink) -> None:
    with pytest.raises(PositionError):
        core.set_goals(["waist", "shoulder"], [0.1, math.radians(150.0)])
    assert core.status().goals_rad == {}


def test_empty_goal_cancels_every_goal(core: BridgeCore, sink: Sink) -> None:
    core.on_telemetry({"neck": reading("neck", 0.0)}, core.clock())
    core.set_goals(["neck"], [0.6])
    core.step()
    assert sink.current["neck"] > 0.0
    assert core.set_goals([], []) == {}
    assert sink.current["neck"] == 0.0
    assert state_of(core) is BridgeState.LISTENING


# ---- what the node publishes ------------------------------------------------------------


def test_joint_state_has_every_positioned_motor_in_profile_order(profile: RobotProfile) -> None:
    readings = {
        "elbow": reading("elbow", -0.4),
        "left_track": reading("left_track", None),
        "waist": reading("waist", 0.3),
    }
    data = joint_state(profile, readings)
    assert data.names == ("waist", "elbow")
    assert data.positions_rad == (0.3, -0.4)
    assert data.velocities_rad_s == (0.5, 0.5)
    assert data.currents_a == (1.25, 1.25)


def test_camera_names(profile: RobotProfile) -> None:
    assert camera_name(profile, 0) == "front"
    assert camera_name(profile, 3) == "rear"
    assert camera_name(profile, None) == "unknown"
    assert camera_name(profile, 9) == "unknown"


def stats(**changes: object) -> LinkStats:
    values: dict[str, object] = {
        "sent": 10,
        "received": 8,
        "telemetry": 7,
        "video": 1,
        "malformed": 2,
        "foreign": 3,
        "send_errors": 0,
        "rcp_rate_hz": 5.0,
        "telemetry_rate_hz": 1.0,
        "video_rate_hz": 0.0,
        "loss_estimate": 0.0,
        "duplicates": 0,
        "reordered": 0,
        "last_valid_age_s": 0.2,
        "send_rate_hz": 5.0,
        "estop_latched": False,
    }
    values.update(changes)
    return LinkStats(**values)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("state", "changes", "level", "message"),
    [
        (LinkState.CONNECTED, {}, DiagnosticLevel.OK, "connected"),
        (LinkState.CONNECTED, {"estop_latched": True}, DiagnosticLevel.WARN, "e-stop|emergency"),
        (LinkState.CONNECTED, {"loss_estimate": 0.3}, DiagnosticLevel.WARN, "loss 30%"),
        (LinkState.CONNECTING, {}, DiagnosticLevel.WARN, "connecting"),
        (LinkState.LOST, {}, DiagnosticLevel.ERROR, "LINK LOST"),
        (LinkState.CLOSED, {}, DiagnosticLevel.ERROR, "closed"),
    ],
)
def test_link_report_levels(
    state: LinkState, changes: dict[str, object], level: DiagnosticLevel, message: str
) -> None:
    report = link_report(state, stats(**changes), "10.0.0.5:10000")
    assert report.level is level
    assert any(part in report.message for part in message.split("|"))
    assert report.hardware_id == "10.0.0.5:10000"


def test_link_report_values() -> None:
    values = dict(link_report(LinkState.CONNECTED, stats(loss_estimate=None), "x").values)
    assert values["malformed datagrams"] == "2"
    assert values["foreign datagrams"] == "3"
    assert values["telemetry loss"] == "n/a"
    assert values["emergency stop latched"] == "false"
    assert values["state"] == "connected"


def test_link_report_has_the_link_docks_figures() -> None:
    figures = stats(delay_s=0.184, jitter_s=0.021, scan_rate_hz=9.5, frame_age_s=(0.12, None))
    values = dict(link_report(LinkState.CONNECTED, figures, "x").values)
    assert values["round trip (ms)"] == "184"
    assert values["delay jitter (ms)"] == "21"
    assert values["scan rate (Hz)"] == "9.5"
    assert values["frame age camera 0 (s)"] == "0.12"
    assert values["frame age camera 1 (s)"] == "n/a"
    assert values["command loss"].startswith("not measurable")
    echoed = dict(link_report(LinkState.CONNECTED, stats(uplink_loss=0.25), "x").values)
    assert echoed["command loss"] == "0.250"


def test_bridge_report(core: BridgeCore, sink: Sink) -> None:
    core.on_cmd_vel(0.1, 0.0)
    core.set_goals(["waist"], [math.radians(10.0)])
    report = bridge_report(core.status(), "sim")
    values = dict(report.values)
    assert report.level is DiagnosticLevel.OK
    assert report.message == "ROS is commanding the robot"
    assert values["drive_linear (m/s)"] == "0.200"
    assert values["joint goals"] == "waist=10.0°"
    assert values["cmd_vel received"] == "1"
    core.override()
    assert bridge_report(core.status(), "sim").level is DiagnosticLevel.WARN


# ---- the arm ------------------------------------------------------------------------------


def _arm_readings(angles: dict[str, float]) -> dict[str, JointReading]:
    return {name: reading(name, value) for name, value in angles.items()}


def test_quaternions_round_trip_and_a_pose_gives_its_pitch(core: BridgeCore) -> None:
    rng = np.random.default_rng(4)
    for _ in range(50):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        rotation = rotation_of(*q)
        assert np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-12)
        assert np.allclose(rotation_of(*quaternion_xyzw(rotation)), rotation, atol=1e-9)
    # A tool pointing outward from the waist axis (x = -0.12 m), 20° down (ROS: pitch +20°
    # about y).
    yaw, pitch = math.atan2(0.35, 0.5 + 0.12), math.radians(20.0)
    turned = rotation_of(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)) @ rotation_of(
        0.0, math.sin(pitch / 2), 0.0, math.cos(pitch / 2)
    )
    target = core.goal_from_pose((0.5, 0.35, 0.4), quaternion_xyzw(turned))
    assert isinstance(target, ToolPose)  # the Engineer's arm has five joints: x, y, z, pitch
    assert target.pitch == pytest.approx(-pitch)
    with pytest.raises(ArmError, match="not zero"):
        core.goal_from_pose((0.5, 0.35, 0.4), (0.0, 0.0, 0.0, 0.0))


def test_arm_goals_and_twists_stop_when_the_link_is_lost(
    core: BridgeCore, sink: Sink, clock: Clock, profile: RobotProfile
) -> None:
    assert profile.arm is not None
    with pytest.raises(ArmError, match="no reading of the waist yet"):
        core.on_pose_goal(ToolPose(0.5, 0.0, 0.5, 0.0))
    core.on_telemetry(_arm_readings(profile.arm.poses["ready"]), clock.now, 0.05)
    core.on_named_pose("look_forward")
    assert state_of(core) is BridgeState.COMMANDING
    clock.now += 0.2
    core.step()
    assert sink.current["shoulder"] > 0.0
    core.on_link_state(LinkState.LOST, "test")
    assert all(sink.current[c] == 0.0 for c in ("waist", "shoulder", "elbow", "neck"))
    with pytest.raises(ArmError, match="LINK LOST"):
        core.on_named_pose("ready")
    core.on_link_state(LinkState.CONNECTED, "back")
    clock.now += 1.0
    assert core.on_arm_twist((0.0, 0.05, 0.0), (0.0, 0.0, 0.0)) is True
    core.step()
    assert sink.current["waist"] > 0.0
    # 0.1 s without a twist: the arm stops by itself.
    clock.now += profile.arm.twist_timeout_s + 0.01
    assert core.step() == [f"arm: no twist for {profile.arm.twist_timeout_s:g} s, jog stopped"]
    assert sink.current["waist"] == 0.0
    with pytest.raises(ArmError, match="no stored pose 'dance'"):
        core.on_named_pose("dance")


# ---- hostile values: bounded before anything computes with them ---------------------------


@pytest.mark.parametrize(
    ("linear", "angular", "expected"),
    [
        (1e308, 0.0, (0.3, 0.0)),  # was a stop: 1e308 / 0.3 overflowed to "a zero maximum"
        (-1e308, 0.0, (-0.3, 0.0)),
        (0.0, -1e308, (0.0, -0.8)),
        (1e308, 1e308, (0.3, 0.3)),  # the ratio (the turn radius) kept
        (5e307, -1e308, (0.3, -0.6)),  # v/0.3 dominates w/0.8
    ],
)
def test_a_huge_cmd_vel_is_clamped_to_the_maxima_and_logged(
    core: BridgeCore,
    *,
    sink: Sink,
    caplog: pytest.LogCaptureFixture,
    linear: float,
    angular: float,
    expected: tuple[float, float],
) -> None:
    caplog.set_level(logging.WARNING, logger="ocu.ros")
    drive = core.on_cmd_vel(linear, angular)
    assert drive is not None
    assert (drive[DRIVE_LINEAR], drive[DRIVE_TURN]) == pytest.approx(expected)
    assert sink.current == drive
    assert "above the maxima (0.30 m/s, 0.80 rad/s): scaled to" in caplog.text
    # Throttled: a publisher at 100 Hz gets one line per interval.
    for _ in range(50):
        core.on_cmd_vel(linear, angular)
    assert caplog.text.count("above the maxima") == 1


@pytest.mark.parametrize("value", [1e308, -1e308, 1e200])
def test_a_huge_arm_twist_is_bounded_before_the_kinematics(
    core: BridgeCore,
    *,
    sink: Sink,
    clock: Clock,
    profile: RobotProfile,
    caplog: pytest.LogCaptureFixture,
    value: float,
) -> None:
    assert profile.arm is not None
    caplog.set_level(logging.WARNING, logger="ocu.ros")
    limits = VelocityLimits(profile)
    core.on_telemetry(_arm_readings(profile.arm.poses["ready"]), clock.now, 0.05)
    for twist in [((value, 0.0, 0.0), (0.0, 0.0, 0.0)), ((0.0, 0.0, 0.0), (0.0, value, value))]:
        for _ in range(5):
            assert core.on_arm_twist(*twist) is True
            clock.now += 0.02
            core.step()  # the old code raised ChainError here: joint values must be finite
            arm = {c: sink.current[c] for c in ("waist", "shoulder", "elbow", "neck")}
            assert all(abs(v) <= limits.get(c) for c, v in arm.items()), arm
        assert state_of(core) is BridgeState.COMMANDING
        core.on_arm_twist((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    assert "arm twist above the maxima (0.150 m/s" in caplog.text


def test_bound_arm_twist_keeps_the_direction_and_the_pitch_sign() -> None:
    axis = np.array([0.0, -1.0, 0.0])
    jog, clamped = bound_arm_twist((3e307, 4e307, 0.0), (0.0, -1e308, 0.0), axis, 0.15, 0.5)
    assert clamped
    assert jog == pytest.approx([0.09, 0.12, 0.0, 0.5])
    jog, clamped = bound_arm_twist((0.01, 0.0, 0.0), (0.0, 0.2, 0.0), axis, 0.15, 0.5)
    assert not clamped
    assert jog == pytest.approx([0.01, 0.0, 0.0, -0.2])
    with pytest.raises(ArmError, match="six finite numbers"):
        bound_arm_twist((math.inf, 0.0, 0.0), (0.0, 0.0, 0.0), axis, 0.15, 0.5)


def test_a_controller_that_raises_halts_its_motion_and_the_core_goes_on(
    core: BridgeCore,
    *,
    sink: Sink,
    clock: Clock,
    profile: RobotProfile,
    caplog: pytest.LogCaptureFixture,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    assert profile.arm is not None
    core.on_telemetry(_arm_readings(profile.arm.poses["ready"]), clock.now, 0.05)
    core.on_cmd_vel(0.25, 0.0)
    # Forward, not sideways: while the chassis drives a jog does without the waist.
    core.on_arm_twist((0.05, 0.0, 0.0), (0.0, 0.0, 0.0))
    clock.now += 0.02
    core.step()
    assert any(sink.current[c] != 0.0 for c in ("shoulder", "elbow", "neck"))
    arm = core._arm
    assert arm is not None

    def broken(now: float) -> dict[str, float]:
        raise FloatingPointError("a fault injected into the arm's control step")

    monkeypatch.setattr(arm, "update", broken)
    clock.now += 0.02
    core.step()  # does not raise
    assert all(sink.current[c] == 0.0 for c in ("waist", "shoulder", "elbow", "neck"))
    assert sink.current[DRIVE_LINEAR] == 0.25  # the other controllers go on
    assert "the arm controller failed (FloatingPointError: a fault injected" in caplog.text
    monkeypatch.undo()
    assert core.on_arm_twist((0.05, 0.0, 0.0), (0.0, 0.0, 0.0)) is True
    clock.now += 0.02
    core.step()
    assert any(sink.current[c] != 0.0 for c in ("shoulder", "elbow", "neck"))


def test_a_long_pose_name_is_refused_without_being_looked_up_or_echoed(
    core: BridgeCore, sink: Sink, clock: Clock, profile: RobotProfile
) -> None:
    assert profile.arm is not None
    core.on_telemetry(_arm_readings(profile.arm.poses["ready"]), clock.now, 0.05)
    with pytest.raises(ArmError) as info:
        core.on_named_pose("x" * 1_000_000)
    assert len(str(info.value)) < 200
    assert "(1000000 characters)" in str(info.value)


def test_quoted_cuts_long_texts() -> None:
    assert quoted("base_link") == "'base_link'"
    assert quoted("y" * 500) == repr("y" * 60) + "... (500 characters)"
