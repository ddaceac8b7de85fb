"""RosBridge hosted in this process, as the console hosts it: ROS control, override, stop."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

import pytest

from ocu.control.commands import VelocityLimits
from ocu.link.live import UdpLink
from ocu.profile import RobotProfile
from ocu.records import Command, LinkState
from ocu.ros.diagnostics import BridgeState
from ocu.sim.simulator import RobotSimulator, SimState

if TYPE_CHECKING:
    from ocu.ros.rosbridge import RosBridge
from tests.ros.conftest import ROSPY_WARNINGS, Collector, needs_ros, wait_for

pytestmark = [pytest.mark.slow, *ROSPY_WARNINGS]


def state_of(bridge: RosBridge) -> BridgeState:
    """The state, read through a call so mypy does not narrow it between asserts."""
    return bridge.state


def drive_stopped(state: SimState) -> bool:
    return state.commanded_velocities["drive_linear"] == 0.0


def forward(speed: float) -> Any:
    from geometry_msgs.msg import Twist

    message = Twist()
    message.linear.x = speed
    return message


@pytest.fixture
def sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    needs_ros()
    simulator = RobotSimulator(profile, telemetry_hz=20.0, video_fps=0.0)
    simulator.start()
    yield simulator
    simulator.stop()


@pytest.fixture
def link(profile: RobotProfile, sim: RobotSimulator) -> Iterator[UdpLink]:
    # The console's GUI thread beats the heartbeat; here nothing does, so no GUI watchdog.
    core = UdpLink(profile, sim.address, gui_alive_timeout_s=None)
    yield core
    core.shutdown()


def test_console_hosts_ros_control_and_the_operator_overrides_it(
    profile: RobotProfile, sim: RobotSimulator, link: UdpLink, ros_client: None
) -> None:
    import rospy
    from geometry_msgs.msg import Twist
    from sensor_msgs.msg import JointState

    from ocu.ros.rosbridge import RosBridge

    states: list[BridgeState] = []
    bridge = RosBridge(
        profile, hardware_id="sim", on_state_changed=lambda state, _text: states.append(state)
    )
    link.start()
    cmd_vel = rospy.Publisher("cmd_vel", Twist, queue_size=10)
    joint_states = Collector("joint_states", JointState)
    try:
        bridge.start(link, VelocityLimits(profile))
        assert wait_for(lambda: cmd_vel.impl.has_connection(rospy.get_caller_id()), 10.0)
        cmd_vel.publish(forward(0.1))
        assert sim.wait_until(lambda s: not drive_stopped(s), 5.0)
        assert sim.state().commanded_velocities["drive_linear"] == pytest.approx(0.2, abs=1e-4)
        assert state_of(bridge) is BridgeState.COMMANDING
        joint_states.wait(lambda m: "waist" in m.name)

        # Any operator input: override first, then the console sends its own command.
        assert bridge.override("slider") is True
        link.set_command(Command())
        assert sim.wait_until(drive_stopped, 2.0)
        rejected = bridge.core.status().rejected_count
        cmd_vel.publish(forward(0.3))
        assert wait_for(lambda: bridge.core.status().rejected_count > rejected, 5.0)
        assert drive_stopped(sim.state())
        assert state_of(bridge) is BridgeState.OVERRIDDEN

        bridge.enable()
        cmd_vel.publish(forward(0.25))
        assert sim.wait_until(lambda s: not drive_stopped(s), 5.0)
    finally:
        bridge.stop()
        cmd_vel.unregister()
        joint_states.close()
    # stop() zeroed what ROS was moving.
    assert sim.wait_until(drive_stopped, 2.0)
    assert states == [
        BridgeState.LISTENING,
        BridgeState.COMMANDING,
        BridgeState.OVERRIDDEN,
        BridgeState.LISTENING,
        BridgeState.COMMANDING,
        BridgeState.OFF,
    ]
    assert not bridge.started


def test_start_twice_is_refused_and_stop_is_idempotent(
    profile: RobotProfile, link: UdpLink, ros_client: None
) -> None:
    from ocu.ros.rosbridge import RosBridge

    bridge = RosBridge(profile)
    bridge.start(link, VelocityLimits(profile))
    try:
        with pytest.raises(RuntimeError, match="already started"):
            bridge.start(link, VelocityLimits(profile))
    finally:
        bridge.stop()
    bridge.stop()
    assert state_of(bridge) is BridgeState.OFF


def test_a_failing_bridge_step_halts_ros_motion_and_the_bridge_goes_on(
    link: UdpLink,
    sim: RobotSimulator,
    ros_client: None,
    monkeypatch: pytest.MonkeyPatch,
    caplog: pytest.LogCaptureFixture,
) -> None:
    from ocu.ros.rosbridge import RosBridge

    bridge = RosBridge(link.profile)
    link.start()
    bridge.start(link, VelocityLimits(link.profile))
    try:
        bridge.core.on_cmd_vel(0.3, 0.0)
        assert sim.wait_until(lambda s: not drive_stopped(s), 5.0)
        step = bridge.core.step
        failing = threading.Event()
        failing.set()

        def broken(now: float | None = None) -> list[str]:
            if failing.is_set():
                failing.clear()
                raise RuntimeError("boom")
            return step(now)

        monkeypatch.setattr(bridge.core, "step", broken)
        assert sim.wait_until(drive_stopped, 2.0)  # halted with the reason...
        assert not failing.is_set()
        halted = "ROS motion halted (the bridge's step failed: RuntimeError: boom)"
        assert wait_for(lambda: halted in caplog.text, 2.0)  # logged just after the zeros
        # ...and still serving: not failed, in control, the next command drives.
        assert not bridge.failed.is_set()
        assert state_of(bridge) is BridgeState.LISTENING
        bridge.core.on_cmd_vel(0.3, 0.0)
        assert sim.wait_until(lambda s: not drive_stopped(s), 5.0)
    finally:
        bridge.stop()
    assert sim.wait_until(drive_stopped, 2.0)


def test_hosted_bridge_learns_link_loss_and_recovery_from_the_link(
    profile: RobotProfile, sim: RobotSimulator, ros_client: None
) -> None:
    from ocu.ros.diagnostics import LinkGate
    from ocu.ros.rosbridge import RosBridge

    def gate() -> LinkGate:
        return bridge.core.link_gate

    # LINK LOST after 0.5 s instead of 3 s, to keep the test short.
    link = UdpLink(profile, sim.address, gui_alive_timeout_s=None, link_lost_after_s=0.5)
    bridge = RosBridge(profile)
    link.start()
    try:
        assert wait_for(lambda: link.state is LinkState.CONNECTED, 5.0)
        sim.cut_link()
        assert wait_for(lambda: link.state is LinkState.LOST, 5.0)
        # The console turns ROS control on while the link is already lost: the bridge
        # subscribes to the running link and never saw the LOST event.
        bridge.start(link, VelocityLimits(profile))
        assert gate() is LinkGate.LOST
        assert bridge.core.on_cmd_vel(0.3, 0.0) is None
        assert link.command.velocity("drive_linear") == 0.0

        restored_at = time.monotonic()
        sim.restore_link()
        assert wait_for(lambda: gate() is LinkGate.RECOVERING, 5.0)  # CONNECTED, subscribed
        assert bridge.core.on_cmd_vel(0.3, 0.0) is None  # the planner's old command
        assert wait_for(lambda: gate() is LinkGate.OPEN, 5.0)  # quiet for 0.5 s
        assert bridge.core.on_cmd_vel(0.3, 0.0) == {"drive_linear": 0.3, "drive_turn": 0.0}
        assert sim.wait_until(lambda s: not drive_stopped(s), 5.0)
        received = [r for r in sim.received_commands() if r.time_s >= restored_at]
        axis = profile.channels["drive_linear"].axis
        first_motion = next(k for k, r in enumerate(received) if r.packet.axes[axis])
        assert first_motion >= 1  # zeros went out before ROS drove again
        assert not any(r.packet.axes[axis] for r in received[:first_motion])

        # LINK LOST while ROS drives: the tee stops it at once.
        sim.cut_link()
        assert wait_for(lambda: gate() is LinkGate.LOST, 5.0)
        assert link.command.velocity("drive_linear") == 0.0
        assert bridge.core.on_cmd_vel(0.3, 0.0) is None
        assert link.command.velocity("drive_linear") == 0.0
        sim.restore_link()
    finally:
        bridge.stop()
        link.shutdown()
