"""`ocu calibrate`: find a robot's wire facts by moving it a little, over any Link.

Steps (docs/calibration.md), each shown to the operator and confirmed in the guided mode:

1. *listen*: telemetry flows, the motors report, position noise is measured;
2. *zero offsets*: the pose now is the zero pose (the guided mode asks for it first);
3. *axis map*: each of the 16 RCP axes is pulsed in turn at a small value, out and back;
   the motor whose speed, echoed speed command or position answers, and with which sign,
   gives the channel -> axis map and each channel's `axis_sign`. Which joint a device is
   cannot be seen from the telemetry: the guided mode asks (a wrong device ID is found so);
4. *joint scale and ticks per radian*: each joint sweeps about where it stands; positions
   against the robot's clock within runs of constant reported speed give ticks per radian
   (`fit_ticks_per_rad`), commanded axis values against reported speeds the axis scale;
5. guided only: a move through a known angle the operator measures; slow moves to the hard
   stops (limits); seed 000 §3.1's drive runs (linear and rotation constants).

Safety: the calibrator moves only while the deadman is held (or the robot is on a stand),
heartbeats the link so a stalled calibrator is zeroed by the link itself, stops on an
e-stop, LINK LOST or an implausible reading (a device moving that should not, a joint past
its excursion budget, a speed it cannot have, a motor still moving after zeros), and sets
zero on every way out. Every automatic move is planned to stay within
`planned_excursion_deg` of where the joint started and is stopped at `max_excursion_deg`.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from ocu.calibrate.core import STEP_TEXT, CalibrationConfig, CalibrationResult, Measured
from ocu.calibrate.guard import CalibrationAbortedError, DeadmanReleasedError
from ocu.calibrate.guided import GuidedSteps
from ocu.calibrate.scan import AxisScan
from ocu.calibrate.sweep import JointSweeps

__all__ = ["CalibrationConfig", "CalibrationResult", "Calibrator", "Measured"]


class Calibrator(AxisScan, JointSweeps, GuidedSteps):
    """One calibration over a link built on `raw_profile(profile)` (see the module docstring).

    The link must be new and not started: the calibrator subscribes, starts it and leaves
    the shutdown (zeros last) to its owner. `run()` blocks; call it on a thread of its own
    when a GUI waits. The steps live in core.py (listen, zero), scan.py, sweep.py and
    guided.py.
    """

    # ---- life ----------------------------------------------------------------------------

    def run(self) -> CalibrationResult:
        """Run every step; never raises for what the robot does (see result.aborted)."""
        started = self.clock()
        self.link.subscribe(self.log)
        self.link.start()
        rate_hz = self.link.rate_hz
        self.link.set_rate_hz(min(self.config.command_rate_hz, self.profile.link.send_rate_max_hz))
        try:
            self._listen()
            self._step("zero", self._zero_offsets)
            self._step("axes", self._scan)
            self._step("sweep", self._sweeps)
            if self.operator.guided:
                self._step("known_angle", self._known_angles)
                self._step("limits", self._limits)
                self._step("drive", self._drive_constants)
        except (CalibrationAbortedError, EOFError) as err:
            self.result.aborted = str(err)
            self.link.emergency_stop(f"calibration: {err}")
            self.operator.say(f"STOPPED: {err}")
        except BaseException:
            self.link.emergency_stop("calibration failed")
            raise
        finally:
            self._zero()
            self.link.set_rate_hz(rate_hz)
            self.link.unsubscribe(self.log)
            self.result.duration_s = self.clock() - started
            self.result.excursion_deg = {
                j.motor.name: math.degrees(j.excursion_rad) for j in self._joints.values()
            }
        return self.result

    def _step(self, name: str, body: Callable[[], None]) -> None:
        """Run a step; a released deadman stops it (zeros) and it starts again when held."""
        text = STEP_TEXT[name]
        if not self.operator.confirm(name, text):
            self.operator.say(f"skipped: {text}")
            return
        self.operator.say(text)
        while True:
            try:
                body()
                return
            except DeadmanReleasedError:
                self._zero()
                self.operator.say("deadman released: stopped; hold it to run the step again")
                self._wait_for_deadman()
                self._settle()
