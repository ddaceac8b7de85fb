"""`ocu inspect` on recordings with zeros where records should be: wall time of the command.

    .venv/bin/python bench/bench_inspect_zeros.py                # 2 GiB sparse, 256 MiB written
    .venv/bin/python bench/bench_inspect_zeros.py --dense-mib 1024

A real recording of 3 s (simulator in this process, telemetry and one extension camera) is
made first. Its header (everything before the first chunk) is then followed by zeros: once
as a sparse file of 2 GiB (truncate: no disk), once with the zeros written (--dense-mib, the
page cache warm). Each file is inspected by `python -m ocu inspect` in a subprocess, timed
from start to exit, and the first warning line it printed is shown. Before the fix the
reader stepped through the zeros nine bytes at a time: about 0.35 s per MB (12 minutes for
2 GB).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from ocu.link.live import UdpLink
from ocu.profile import load_profile
from ocu.record.reader import Recording
from ocu.record.recorder import Recorder
from ocu.records import CameraRequest, LinkEvent, TelemetryFrame
from ocu.sim.simulator import RobotSimulator

SPARSE_BYTES = 2 * 1024**3
RECORD_S = 3.0


def record(path: Path) -> None:
    """A few seconds of a real session into path."""
    profile = load_profile()
    sim = RobotSimulator(profile, telemetry_hz=20.0, video_fps=0.0, extended=True)
    sim.start()
    enough = threading.Event()
    received: list[TelemetryFrame] = []

    def listen(event: LinkEvent) -> None:
        if isinstance(event, TelemetryFrame):
            received.append(event)
            if len(received) >= RECORD_S * 20:
                enough.set()

    recorder = Recorder(profile, chunk_bytes=64 * 1024)
    link = UdpLink(profile, sim.address, listener=listen, gui_alive_timeout_s=None, extension=True)
    link.set_stream_request([CameraRequest(0, 160, 120, 10)])
    recorder.attach(link)
    recorder.start(path)
    link.start()
    try:
        if not enough.wait(RECORD_S * 5):
            raise SystemExit("the simulator sent too little telemetry")
    finally:
        link.shutdown()
        sim.stop()
    recorder.stop()


def inspect(path: Path) -> tuple[float, int, str]:
    """Wall seconds, exit code and the first warning line of `ocu inspect path`."""
    started = time.perf_counter()
    result = subprocess.run(
        [sys.executable, "-m", "ocu", "inspect", str(path)],
        capture_output=True,
        text=True,
        check=False,
    )
    elapsed = time.perf_counter() - started
    warning = next((line for line in result.stdout.splitlines() if "WARNING" in line), "")
    return elapsed, result.returncode, warning or result.stderr.strip()[:120]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dense-mib", type=int, default=256, help="written zeros, MiB")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="ocu-bench-inspect-") as folder:
        real = Path(folder) / "real.mcap"
        record(real)
        with Recording(real) as recording:
            header_bytes = recording.chunks[0].offset
        head = real.read_bytes()[:header_bytes]
        sparse = Path(folder) / "sparse.mcap"
        sparse.write_bytes(head)
        os.truncate(sparse, SPARSE_BYTES)
        dense = Path(folder) / "dense.mcap"
        with dense.open("wb") as stream:
            stream.write(head)
            block = bytes(1024**2)
            for _ in range(args.dense_mib):
                stream.write(block)
        print(f"header {header_bytes} B; the real recording {real.stat().st_size / 1e6:.2f} MB")
        for name, path in (("real", real), ("sparse", sparse), ("dense", dense)):
            elapsed, code, warning = inspect(path)
            size_mb = path.stat().st_size / 1e6
            print(f"{name:<7} {size_mb:>9.1f} MB  {elapsed:6.2f} s  exit {code}  {warning}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
