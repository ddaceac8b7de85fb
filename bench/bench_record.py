"""Recording cost with four cameras at 30 fps: CPU added, MB per minute, arrival-to-paint.

    .venv/bin/python bench/bench_record.py                 # 4 x 10 s phases, off/on/off/on
    .venv/bin/python bench/bench_record.py --phase-s 20 --pairs 3 --raw-only

The simulator runs in its own process (`ocu-sim --extended`) and streams every camera
through the protocol extension at the profile's stream request (640x480, 30 fps); this
process is the console's video path: a LinkThread (link loop + "ocu-video" decoder) and the
console's VideoPanel shown offscreen at 1280x1000, image correction off (as in
bench_video.py's "extended" mode). Phases with the recorder off
and on alternate, so both baselines share the same machine load. Per phase: this process's
CPU (user + system, in % of one core) and its threads', video frames received and painted
per second, arrival-to-paint latency (the view's frame_painted age: the link loop got the
last fragment -> first paint; p50/p95/p99) and, while recording, the file's growth in MB
per minute and the recorder's dropped messages.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

from PySide6.QtCore import QEventLoop, QTimer
from PySide6.QtWidgets import QApplication

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from common import percentile, video_console

from ocu.link.base import Link
from ocu.link.live import UdpLink
from ocu.profile import load_profile
from ocu.record.recorder import Recorder
from ocu.sim.launcher import SimulatorProcess
from ocu.video.correction import CorrectionSettings
from ocu.widgets.video import VideoPanel

PANEL_SIZE = (1280, 1000)


class PaintAges:
    """Arrival-to-paint age of every frame the console's video view paints for the first time."""

    def __init__(self, panel: VideoPanel) -> None:
        self.ages_s: list[float] = []
        panel.view.frame_painted.connect(self._on_painted)

    def _on_painted(self, camera: int, age_s: float) -> None:
        self.ages_s.append(age_s)


@dataclass
class Phase:
    """What one phase measured."""

    recording: bool
    seconds: float
    cpu_percent: float
    painted_fps: float
    p50_ms: float
    p95_ms: float
    p99_ms: float
    received_fps: float
    threads_percent: dict[str, float]
    mb_per_min: float = 0.0
    dropped: int = 0


def cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


TICKS_PER_S = os.sysconf("SC_CLK_TCK")
THREADS = ("gui", "ocu-link", "ocu-video", "ocu-record")


def thread_cpu_s() -> dict[str, float]:
    """CPU seconds of this process's threads by name (Qt names its QThreads natively)."""
    names = {t.native_id: t.name for t in threading.enumerate()}
    names[threading.main_thread().native_id] = "gui"
    result = dict.fromkeys(THREADS, 0.0)
    for task in os.listdir("/proc/self/task"):
        try:
            stat = Path(f"/proc/self/task/{task}/stat").read_text()
            comm = Path(f"/proc/self/task/{task}/comm").read_text().strip()
        except OSError:
            continue  # the thread ended meanwhile
        name = names.get(int(task), comm)
        if name in result:
            fields = stat.rsplit(")", 1)[1].split()
            result[name] += (int(fields[11]) + int(fields[12])) / TICKS_PER_S
    return result


def run_for(seconds: float) -> None:
    loop = QEventLoop()
    QTimer.singleShot(round(seconds * 1000), loop.quit)
    loop.exec()


def measure(
    ages: PaintAges, core: Link, seconds: float, recorder: Recorder | None, path: Path
) -> Phase:
    if recorder is not None:
        recorder.start(path)
    run_for(1.0)  # settle after the switch
    ages.ages_s.clear()
    size0 = path.stat().st_size if recorder is not None else 0
    cpu0, threads0, video0, t0 = cpu_s(), thread_cpu_s(), core.stats().video, time.monotonic()
    run_for(seconds)
    cpu1, threads1, video1, t1 = cpu_s(), thread_cpu_s(), core.stats().video, time.monotonic()
    elapsed = t1 - t0
    latencies = [x * 1000 for x in ages.ages_s]
    phase = Phase(
        recording=recorder is not None,
        seconds=elapsed,
        cpu_percent=(cpu1 - cpu0) / elapsed * 100,
        painted_fps=len(latencies) / elapsed,
        p50_ms=percentile(latencies, 50),
        p95_ms=percentile(latencies, 95),
        p99_ms=percentile(latencies, 99),
        received_fps=(video1 - video0) / elapsed,
        threads_percent={n: (threads1[n] - threads0[n]) / elapsed * 100 for n in THREADS},
    )
    if recorder is not None:
        phase.mb_per_min = (path.stat().st_size - size0) / 1e6 / elapsed * 60
        phase.dropped = recorder.stop().dropped
    return phase


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--phase-s", type=float, default=10.0, help="seconds per phase")
    parser.add_argument("--pairs", type=int, default=2, help="off/on pairs")
    parser.add_argument("--raw-only", action="store_true", help="no CompressedImage copies")
    args = parser.parse_args()

    profile = load_profile()
    cameras = len(profile.link.camera_names)
    app = QApplication.instance() or QApplication([])
    sim_args = ["--extended", "--video-fps", "0", "--telemetry-hz", "20", "--log-level", "WARNING"]
    with SimulatorProcess(None, sim_args) as sim:
        core = UdpLink(profile, sim.address, extension=True)
        recorder = Recorder(profile, decoded_video=not args.raw_only)
        recorder.attach(core)
        _model, link, panel = video_console(profile, core)
        for camera in range(cameras):
            panel.set_correction(camera, CorrectionSettings(colour="off", undistort=False))
        panel.resize(*PANEL_SIZE)
        panel.show()
        ages = PaintAges(panel)
        link.start()
        phases: list[Phase] = []
        with tempfile.TemporaryDirectory() as tmp:
            try:
                run_for(3.0)  # the extension handshake and the first frames
                if not panel.extension_active:
                    raise RuntimeError("the simulator did not answer with the extension")
                for index in range(args.pairs):
                    phases.append(measure(ages, core, args.phase_s, None, Path(tmp) / "none"))
                    path = Path(tmp) / f"bench-{index}.mcap"
                    phases.append(measure(ages, core, args.phase_s, recorder, path))
            finally:
                recorder.stop()
                link.shutdown()
                panel.close()
        ext = profile.extension
        assert ext is not None
        width, height, fps = ext.stream_width_px, ext.stream_height_px, ext.stream_fps
        del app

    print(
        f"recording cost: {cameras} cameras at {width}x{height} {fps} fps over the "
        f"extension, {'raw only' if args.raw_only else 'raw + CompressedImage'}, zstd chunks"
    )
    threads = " ".join(f"{name:>10}" for name in THREADS)
    print(
        f"{'phase':<10} {'CPU %':>6} {threads} {'recv/s':>7} {'painted/s':>9} {'p50 ms':>7} "
        f"{'p95 ms':>7} {'p99 ms':>7} {'MB/min':>7} {'dropped':>8}"
    )
    for phase in phases:
        name = "recording" if phase.recording else "off"
        per_thread = " ".join(f"{phase.threads_percent[n]:>10.1f}" for n in THREADS)
        print(
            f"{name:<10} {phase.cpu_percent:>6.1f} {per_thread} {phase.received_fps:>7.1f} "
            f"{phase.painted_fps:>9.1f} {phase.p50_ms:>7.1f} {phase.p95_ms:>7.1f} "
            f"{phase.p99_ms:>7.1f} {phase.mb_per_min:>7.0f} {phase.dropped:>8}"
        )
    off = [p for p in phases if not p.recording]
    on = [p for p in phases if p.recording]

    def mean(values: list[float]) -> float:
        return statistics.fmean(values)

    cpu_off = mean([p.cpu_percent for p in off])
    cpu_on = mean([p.cpu_percent for p in on])
    link_added = mean([p.threads_percent["ocu-link"] for p in on]) - mean(
        [p.threads_percent["ocu-link"] for p in off]
    )
    print(
        f"CPU added by recording: {cpu_on - cpu_off:+.1f} % of one core "
        f"(off {cpu_off:.1f} %, on {cpu_on:.1f} %)"
    )
    print(
        "  the ocu-record thread itself: "
        f"{mean([p.threads_percent['ocu-record'] for p in on]):.1f} % of one core; "
        f"the link loop (callbacks): {link_added:+.1f} %"
    )
    print(f"file growth: {mean([p.mb_per_min for p in on]):.0f} MB per minute")
    print(
        f"arrival-to-paint p50 {mean([p.p50_ms for p in off]):.1f} -> "
        f"{mean([p.p50_ms for p in on]):.1f} ms, p95 {mean([p.p95_ms for p in off]):.1f} -> "
        f"{mean([p.p95_ms for p in on]):.1f} ms; painted "
        f"{mean([p.painted_fps for p in off]):.1f} -> {mean([p.painted_fps for p in on]):.1f} "
        "frames/s"
    )


if __name__ == "__main__":
    main()
