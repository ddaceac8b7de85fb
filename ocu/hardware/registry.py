"""The hardware plug-ins by name: one registration line each (docs/hardware.md)."""

from __future__ import annotations

from ocu.core.hardware import HardwareRegistry
from ocu.hardware import engineer, ur, xarm

HARDWARE = HardwareRegistry()
HARDWARE.register("engineer", engineer.over_udp)
HARDWARE.register("engineer-sim", engineer.simulated)
HARDWARE.register("engineer-recording", engineer.recording)
HARDWARE.register("ur", ur.over_tcp)
HARDWARE.register("ur-sim", ur.simulated)
HARDWARE.register("xarm", xarm.over_serial)
HARDWARE.register("xarm-sim", xarm.simulated)
