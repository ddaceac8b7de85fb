"""The robot simulator: a UDP server that stands in for the Servosila Engineer."""

from ocu.sim.faults import FaultConfig
from ocu.sim.simulator import ReceivedRcp, RobotSimulator, SimState

__all__ = ["FaultConfig", "ReceivedRcp", "RobotSimulator", "SimState"]
