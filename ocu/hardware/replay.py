"""The hardware a recording stands for in a replay: its joints and capabilities.

A replay of a Universal Robots arm's recording is the UR's six joints with the capability
"arm" (as `ocu.hardware.ur` gives a live one), an xArm's its six servos with "arm" and
"battery"; any other recording is the Engineer's.
"""

from __future__ import annotations

from collections.abc import Callable

from ocu.core.hardware import HardwareComponent
from ocu.hardware.engineer import engineer_component
from ocu.hardware.ur import UR_CAPABILITIES, ur_joints
from ocu.hardware.xarm import XARM_CAPABILITIES, xarm_joints
from ocu.link.base import Link
from ocu.record.replay_link import ReplayLink


def replay_hardware(
    source: ReplayLink,
) -> tuple[Callable[[Link], HardwareComponent], frozenset[str] | None]:
    """The console's `hardware_for` and `capabilities` for this replay (None: the
    Engineer's, from its profile)."""
    xarm = source.recording.xarm()
    if xarm is not None:

        def xarm_replay(link: Link) -> HardwareComponent:
            return HardwareComponent(
                "xarm-replay", link, joints=xarm_joints(xarm), capabilities=XARM_CAPABILITIES
            )

        return xarm_replay, XARM_CAPABILITIES
    arm = source.recording.ur_arm()
    if arm is None:
        return engineer_component, None

    def ur_replay(link: Link) -> HardwareComponent:
        return HardwareComponent(
            "ur-replay", link, joints=ur_joints(arm), capabilities=UR_CAPABILITIES
        )

    return ur_replay, UR_CAPABILITIES
