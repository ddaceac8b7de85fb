"""What every UR codec shares: the joints, the modes, the error (docs/ur.md)."""

from __future__ import annotations

from enum import IntEnum

from ocu.protocol.errors import ProtocolError

JOINTS = 6

Vector6 = tuple[float, float, float, float, float, float]
Vector3 = tuple[float, float, float]


class UrProtocolError(ProtocolError):
    """A UR packet or URScript line that does not follow the controller's wire format."""


class RobotMode(IntEnum):
    """The controller's robot mode (ur_client_library datatypes.h; the realtime doc)."""

    NO_CONTROLLER = -1
    DISCONNECTED = 0
    CONFIRM_SAFETY = 1
    BOOTING = 2
    POWER_OFF = 3
    POWER_ON = 4
    IDLE = 5
    BACKDRIVE = 6
    RUNNING = 7
    UPDATING_FIRMWARE = 8


class SafetyMode(IntEnum):
    """The controller's safety mode (ur_client_library datatypes.h, 1..22)."""

    NORMAL = 1
    REDUCED = 2
    PROTECTIVE_STOP = 3
    RECOVERY = 4
    SAFEGUARD_STOP = 5
    SYSTEM_EMERGENCY_STOP = 6
    ROBOT_EMERGENCY_STOP = 7
    VIOLATION = 8
    FAULT = 9
    VALIDATE_JOINT_ID = 10
    UNDEFINED_SAFETY_MODE = 11
    AUTOMATIC_MODE_SAFEGUARD_STOP = 12
    SYSTEM_THREE_POSITION_ENABLING_STOP = 13
    TP_THREE_POSITION_ENABLING_STOP = 14
    IMMI_EMERGENCY_STOP = 15
    IMMI_SAFEGUARD_STOP = 16
    PROFISAFE_WAITING_FOR_PARAMETERS = 17
    PROFISAFE_AUTOMATIC_MODE_SAFEGUARD_STOP = 18
    PROFISAFE_SAFEGUARD_STOP = 19
    PROFISAFE_EMERGENCY_STOP = 20
    SAFETY_API_SAFEGUARD_STOP = 22
