"""The xArm link's pieces below its loop: the serial port (pyserial), the records it hands
on (a position reply as telemetry, a battery reply as status), and a servo's setpoint as the
board moves it. The board's codec is ocu.protocol.xarm.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable
from dataclasses import dataclass

from ocu.link.base import LinkError

PortOpener = Callable[[str, int], "SerialPort"]


class SerialPort:
    """The serial device, opened raw with pyserial: bytes in and out, a file descriptor."""

    def __init__(self, path: str, baud: int) -> None:
        try:
            import serial  # pyserial; imported here so that the codec and the simulator need not
        except ImportError as err:
            raise OSError(f"{path}: pyserial is not installed ({err})") from err

        try:
            self._serial = serial.Serial(path, baudrate=baud, timeout=0, write_timeout=0.5)
        except (serial.SerialException, ValueError) as err:
            raise OSError(f"{path}: {err}") from err
        self._error = serial.SerialException

    def fileno(self) -> int:
        """The descriptor to wait on."""
        return int(self._serial.fileno())

    def read(self) -> bytes:
        """What has arrived (b"" if nothing); OSError if the port failed."""
        try:
            return bytes(self._serial.read(4096))
        except self._error as err:
            raise OSError(str(err)) from err

    def write(self, data: bytes) -> None:
        """Send `data` whole; OSError if the port failed."""
        try:
            self._serial.write(data)
        except self._error as err:
            raise OSError(str(err)) from err

    def close(self) -> None:
        """Close the device."""
        with contextlib.suppress(Exception):
            self._serial.close()


@dataclass(frozen=True)
class XarmMotor:
    """One servo's reading as the board sent it (position in servo units)."""

    device_id: int
    position: int
    state: int = 0
    mode: int = 0
    status: int = 0


@dataclass(frozen=True)
class XarmTelemetry:
    """One position reply: the link's count of replies, and the servos'."""

    tick: int
    motors: tuple[XarmMotor, ...]


@dataclass(frozen=True)
class XarmStatus:
    """A battery reply (the board measures nothing else of it)."""

    voltage_mv: int | None
    charge_permille: int | None = None
    headlight_on: bool | None = None
    roll_mrad: int | None = None
    pitch_mrad: int | None = None
    yaw_mrad: int | None = None


@dataclass
class Ramp:
    """A servo's setpoint as the board moves it: linear from `start` to `end` over time."""

    start: float
    end: float
    at: float
    duration_s: float

    def value(self, now: float) -> float:
        """The setpoint at `now`."""
        if self.duration_s <= 0.0 or now >= self.at + self.duration_s:
            return self.end
        return self.start + (self.end - self.start) * max(0.0, now - self.at) / self.duration_s

    def moving(self, now: float) -> bool:
        """Whether the setpoint is still on its way."""
        return self.duration_s > 0.0 and now < self.at + self.duration_s


def check_port(path: str) -> None:
    """LinkError unless `path` looks like a serial device that exists."""
    if not path:
        raise LinkError("no serial device given (e.g. /dev/ttyUSB0)")
    if not os.path.exists(path):
        raise LinkError(f"no serial device {path}")
