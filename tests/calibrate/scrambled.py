"""A calibration against the real simulator playing a scrambled robot, with its ground truth."""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Collection
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from ocu.calibrate.guard import Deadman, OnStand, StopSignal
from ocu.calibrate.operator import AutoOperator, Operator
from ocu.calibrate.raw import raw_profile
from ocu.calibrate.session import CalibrationConfig, CalibrationResult, Calibrator
from ocu.calibrate.writer import write_calibrated_profile
from ocu.link.live import VirtualLink
from ocu.net.transport import VirtualWire
from ocu.profile import RobotProfile, load_profile, load_profile_data, parse_profile
from ocu.sim.faults import FaultConfig
from ocu.sim.scramble import scramble_profile_data
from ocu.sim.simulator import ReceivedRcp, RobotSimulator, StateRecorder

BASE_DATA: dict[str, Any] = load_profile_data()
BASE = load_profile()
RUN_TIMEOUT_S = 240.0


@dataclass
class Outcome:
    """What a calibration found, the truth it had to find, and what the robot went through."""

    truth: RobotProfile
    result: CalibrationResult
    true_excursion_deg: dict[str, float]
    received: list[ReceivedRcp]
    profile_path: Path | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def profile(self) -> RobotProfile:
        """The calibrated profile as written and loaded back."""
        assert self.profile_path is not None
        return load_profile(self.profile_path)


def scrambled_truth(seed: int, *, ids: bool = False) -> RobotProfile:
    """The robot `ocu-sim --scramble SEED` plays."""
    return parse_profile(scramble_profile_data(BASE_DATA, seed, ids=ids))


def calibrate_scrambled(
    seed: int,
    tmp_path: Path,
    *,
    ids: bool = False,
    telemetry_hz: float = 20.0,
    faults: FaultConfig | None = None,
    noise_deg: float = 0.0,
    operator: Callable[[RobotSimulator], Operator] | None = None,
    deadman: Deadman | None = None,
    stop: StopSignal | None = None,
    config: CalibrationConfig | None = None,
    during: Callable[[RobotSimulator, StopSignal, threading.Event], None] | None = None,
) -> Outcome:
    """Calibrate the scrambled robot over a virtual wire; `during(sim, stop, finished)` runs
    alongside, on the test's thread, while the calibrator runs on its own (`finished` is set
    when it returns)."""
    truth = scrambled_truth(seed, ids=ids)
    wire = VirtualWire()
    sim = RobotSimulator(
        truth,
        transport=wire.robot,
        telemetry_hz=telemetry_hz,
        video_fps=0.0,
        faults=faults,
        noise_deg=noise_deg,
        seed=seed,
    )
    stop = stop or StopSignal()
    outcome: list[CalibrationResult] = []
    finished = threading.Event()
    sent: list[int] = []
    try:
        with sim:
            recorder = StateRecorder(sim)
            link = VirtualLink(raw_profile(BASE), wire.ocu)
            calibrator = Calibrator(
                link,
                BASE,
                operator(sim) if operator is not None else AutoOperator(),
                deadman=deadman or OnStand(),
                stop=stop,
                config=config,
            )

            def run() -> None:
                try:
                    outcome.append(calibrator.run())
                finally:
                    link.shutdown()
                    sent.append(link.stats().sent)
                    finished.set()

            thread = threading.Thread(target=run, name="calibrator-under-test")
            thread.start()
            try:
                if during is not None:
                    during(sim, stop, finished)
            finally:
                thread.join(RUN_TIMEOUT_S)
                recorder.stop()
            assert not thread.is_alive(), "the calibration did not end"
            # Every RCP sent has reached the robot (or been lost) before it is read.
            assert sim.wait_until(lambda s: s.rcp_count + s.dropped_to_robot >= sent[0], 5.0)
            received = sim.received_commands()
    finally:
        wire.close()
    result = outcome[0]
    start = recorder.samples[0].joints_rad
    excursion = {
        name: math.degrees(max(abs(s.joints_rad[name] - start[name]) for s in recorder.samples))
        for name in start
    }
    done = Outcome(truth, result, excursion, received)
    if result.aborted is None:
        done.profile_path = tmp_path / f"calibrated-{seed}.toml"
        write_calibrated_profile(
            done.profile_path, BASE_DATA, result, robot="virtual", base_name="engineer.toml"
        )
    return done


def assert_recovered(
    outcome: Outcome, *, tolerance: float = 0.02, to_the_stops: Collection[str] = ()
) -> None:
    """The axis map and directions exactly, scales and ticks per radian within tolerance;
    no joint moved 10° but those the operator sent `to_the_stops` (the guided limits step)."""
    truth, found = outcome.truth, outcome.profile
    for name, channel in truth.channels.items():
        assert found.channels[name].axis == channel.axis, name
        assert found.channels[name].axis_sign == channel.axis_sign, name
        assert found.provenance(f"channels.{name}.axis") == "measured"
        if truth.motor_for_channel(name) is not None:
            assert found.channels[name].axis_per_unit == pytest.approx(
                channel.axis_per_unit, rel=tolerance
            ), name
    for name, motor in truth.motors.items():
        if motor.channel is None:
            continue
        assert found.motors[name].ticks_per_rad == pytest.approx(
            motor.ticks_per_rad, rel=tolerance
        ), name
        assert found.motors[name].zero_offset_ticks == pytest.approx(
            motor.zero_offset_ticks, abs=0.5 * (motor.ticks_per_rad or 0) * math.pi / 180
        ), name
    bounded = {n: d for n, d in outcome.true_excursion_deg.items() if n not in to_the_stops}
    assert max(bounded.values()) < 10.0, bounded
