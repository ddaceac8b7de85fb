"""A recording session in a process of its own, for the kill -9 and file-size-limit tests.

    python -m tests.record.record_session FILE --until-killed
    python -m tests.record.record_session FILE --file-size-limit BYTES

Both record a simulator (in this process) through a UdpLink. --until-killed prints "recording"
and runs until it is killed. --file-size-limit caps this process's file size (RLIMIT_FSIZE,
with SIGXFSZ ignored, so writes past it fail with EFBIG as on a full disk), waits for the
recorder to report the error, checks that the link still sends commands afterwards and
prints a JSON report.
"""

from __future__ import annotations

import argparse
import json
import resource
import signal
import sys
import threading
import time
from pathlib import Path

from ocu.link.live import UdpLink
from ocu.profile import load_profile
from ocu.record.recorder import Recorder
from ocu.sim.simulator import RobotSimulator

DEADLINE_S = 20.0
RCPS_AFTER_ERROR = 5


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("file", type=Path)
    parser.add_argument("--until-killed", action="store_true")
    parser.add_argument("--file-size-limit", type=int)
    args = parser.parse_args()

    profile = load_profile()
    errors: list[str] = []
    failed = threading.Event()

    def on_error(message: str) -> None:
        errors.append(message)
        failed.set()

    sim = RobotSimulator(profile, telemetry_hz=50.0, video_fps=20.0, video_size=(160, 120))
    sim.start()
    recorder = Recorder(profile, chunk_bytes=32 * 1024, flush_period_s=0.2, on_error=on_error)
    link = UdpLink(profile, sim.address, gui_alive_timeout_s=None, send_rate_hz=20.0)
    recorder.attach(link)
    if args.file_size_limit is not None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (args.file_size_limit, args.file_size_limit))
    recorder.start(args.file)
    link.start()
    link.set_velocities(waist=0.2)
    try:
        if args.until_killed:
            print("recording", flush=True)
            while True:
                time.sleep(1.0)
        if not failed.wait(DEADLINE_S):
            print(json.dumps({"error": None}))
            return 1
        rcp_at_error = sim.state().rcp_count
        link.set_velocities(waist=-0.2)
        commands_flow = sim.wait_until(
            lambda s: (
                s.rcp_count >= rcp_at_error + RCPS_AFTER_ERROR
                and s.commanded_velocities.get("waist", 0.0) < 0.0
            ),
            DEADLINE_S,
        )
        report = {
            "error": errors[0],
            "recording": recorder.recording,
            "commands_flow_after_error": commands_flow,
        }
        stats = recorder.stop()
        report["stats_error"] = stats.error
        print(json.dumps(report), flush=True)
        return 0
    finally:
        link.shutdown()
        sim.stop()
        recorder.stop()


if __name__ == "__main__":
    sys.exit(main())
