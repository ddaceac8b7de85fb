"""Today's main for bench_arm_moves: the end of a move as it was before issue 21's fix.

The command was sized for the last tick interval (not the horizon of late ticks), the move
fed forward the profile's instantaneous speed with the full gain, and a joint was driven
back on the prediction alone. Swapped into a live console model by class.
"""

from __future__ import annotations

from ocu.console.model import ConsoleModel
from ocu.control.arm import ArmController
from ocu.control.position import PositionController

# A horizon this short makes the move's feed-forward the profile's speed now and leaves the
# gain as it is: main's law.
INSTANT_S = 1e-4


class MainPosition(PositionController):
    """Main's position controller: the last interval, reversals on the prediction."""

    arm_moving = False

    @property
    def tick_horizon_s(self) -> float:
        return INSTANT_S if self.arm_moving else self._period_s

    def may_reverse(self, joint: str) -> bool:
        return True


class MainArm(ArmController):
    """Main's arm controller (its moves use the instantaneous law above)."""

    def update(self, now: float) -> dict[str, float]:
        assert isinstance(self.position, MainPosition)
        self.position.arm_moving = True
        try:
            return super().update(now)
        finally:
            self.position.arm_moving = False


def use_main_controllers(model: ConsoleModel) -> None:
    """Give a console model main's position and arm controllers (the same state)."""
    model.controller.__class__ = MainPosition
    assert model.arm is not None
    model.arm.controller.__class__ = MainArm
