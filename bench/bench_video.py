"""Video benchmark: frames shown, drops, arrival-to-paint latency, CPU and memory of the OCU.

    .venv/bin/python bench/bench_video.py                      # all three modes, 60 s each
    .venv/bin/python bench/bench_video.py extended --seconds 20

Modes (the simulator runs as a separate `ocu-sim` process on 127.0.0.1, 640x480 JPEGs):

- extended:  four cameras at 30 fps each over the protocol extension, no correction;
- corrected: the same with gray-world colour correction and undistortion on every camera;
- vendor:    the vendor protocol, one camera at 30 fps.

The OCU side is the real thing: a UdpLink in a QtLink bound to a ConsoleModel, the ocu-video
decoder thread and a VideoPanel shown (offscreen) at 1280x1000, run by the Qt event loop. Age
is paint time minus arrival time (time.monotonic) of each frame's first paint. CPU is this
process only (user + system, percent of one core); RSS growth is measured from the end of the
warm-up.
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import time
from dataclasses import dataclass, field

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

import cv2
from PySide6.QtCore import QEventLoop, QTimer
from PySide6.QtWidgets import QApplication

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from common import video_console

from ocu.link.live import UdpLink
from ocu.profile import RobotProfile, load_profile
from ocu.qt.link import QtLink
from ocu.sim.launcher import SimulatorProcess
from ocu.video.correction import CorrectionSettings
from ocu.widgets.video import VideoPanel, percentile

MODES = ("extended", "corrected", "vendor")
FPS = 30
SIZE = "640x480"
PANEL_SIZE = (1280, 1000)


def rss_mb() -> float:
    """Resident set size of this process in MB."""
    with open("/proc/self/statm", encoding="ascii") as statm:
        pages = int(statm.read().split()[1])
    return pages * os.sysconf("SC_PAGE_SIZE") / 1e6


def cpu_s() -> float:
    """User plus system CPU seconds of this process (all its threads)."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


@dataclass
class Run:
    """What one mode measured."""

    mode: str
    seconds: float
    cameras: list[int]
    ages_ms: dict[int, list[float]] = field(default_factory=dict)
    shown_fps: dict[int, float] = field(default_factory=dict)
    dropped: dict[int, int] = field(default_factory=dict)
    lost_frames: int = 0
    cpu_percent: float = 0.0
    rss_growth_mb: float = 0.0
    rss_end_mb: float = 0.0
    correction_ms: list[float] = field(default_factory=list)


def wait(app: QApplication, seconds: float) -> None:
    """Run a Qt event loop for a while (QApplication.quit would close the windows)."""
    loop = QEventLoop(app)
    QTimer.singleShot(round(seconds * 1000), loop.quit)
    loop.exec()


def drops(panel: VideoPanel, link: QtLink, camera: int) -> int:
    """Frames of a camera that arrived whole but were never painted."""
    decoded = link.decoder.stats(camera)
    return decoded.skipped + link.frames.replaced(camera) + panel.view.stats(camera).not_shown


def run_mode(
    app: QApplication, profile: RobotProfile, mode: str, seconds: float, warmup_s: float
) -> Run:
    """Measure one mode."""
    extended = mode != "vendor"
    args = ["--telemetry-hz", "1", "--video-size", SIZE, "--log-level", "WARNING"]
    args += ["--extended", "--video-fps", "0"] if extended else ["--video-fps", str(FPS)]
    with SimulatorProcess(extra_args=args) as sim:
        _model, link, panel = video_console(
            profile, UdpLink(profile, sim.address, extension=extended)
        )
        panel.resize(*PANEL_SIZE)
        panel.show()
        cameras = list(range(len(profile.link.camera_names))) if extended else [0]
        for camera in range(len(profile.link.camera_names)):
            settings = CorrectionSettings(
                colour="gray_world" if mode == "corrected" else "off",
                undistort=mode == "corrected",
            )
            panel.set_correction(camera, settings)
        if not extended:
            panel.select_camera(0)
        link.start()
        try:
            wait(app, warmup_s)
            if extended and not panel.extension_active:
                raise RuntimeError("the simulator did not answer with the extension")
            run = Run(mode, seconds, cameras)
            run.ages_ms = {camera: [] for camera in cameras}

            def painted(camera: int, age_s: float) -> None:
                if camera in run.ages_ms:
                    run.ages_ms[camera].append(age_s * 1000.0)
                    frame = panel.view.current_frame(camera)
                    if frame is not None and frame.decoded is not None:
                        run.correction_ms.append(frame.decoded.correction.total_ms)

            drops_before = {camera: drops(panel, link, camera) for camera in cameras}
            video_before = link.link.video_stats()
            rss_before = rss_mb()
            cpu_before = cpu_s()
            start = time.monotonic()
            panel.view.frame_painted.connect(painted)
            wait(app, seconds)
            panel.view.frame_painted.disconnect(painted)
            elapsed = time.monotonic() - start
            run.cpu_percent = (cpu_s() - cpu_before) / elapsed * 100.0
            run.rss_end_mb = rss_mb()
            run.rss_growth_mb = run.rss_end_mb - rss_before
            video_after = link.link.video_stats()
            run.lost_frames = (video_after.truncated + video_after.expired) - (
                video_before.truncated + video_before.expired
            )
            for camera in cameras:
                run.shown_fps[camera] = len(run.ages_ms[camera]) / elapsed
                run.dropped[camera] = drops(panel, link, camera) - drops_before[camera]
            return run
        finally:
            link.shutdown()
            panel.close()
            panel.deleteLater()


def report(run: Run, names: tuple[str, ...]) -> None:
    """Print one mode's figures."""
    all_ages = [age for ages in run.ages_ms.values() for age in ages]
    print(f"\n## {run.mode} ({run.seconds:.0f} s, {SIZE}, {FPS} fps per camera)")
    print("| camera | shown fps | dropped | lost in transit | age p50 ms | age p99 ms |")
    print("|---|---:|---:|---:|---:|---:|")
    for camera in run.cameras:
        ages = run.ages_ms[camera]
        print(
            f"| {names[camera]} | {run.shown_fps[camera]:.1f} | {run.dropped[camera]} | "
            f"{'' if camera else run.lost_frames} | {percentile(ages, 50):.1f} | "
            f"{percentile(ages, 99):.1f} |"
        )
    print(
        f"| all | {sum(run.shown_fps.values()):.1f} | {sum(run.dropped.values())} | "
        f"{run.lost_frames} | {percentile(all_ages, 50):.1f} | {percentile(all_ages, 99):.1f} |"
    )
    correction = (
        f", correction p50 {percentile(run.correction_ms, 50):.2f} ms "
        f"p99 {percentile(run.correction_ms, 99):.2f} ms per frame"
        if run.correction_ms and max(run.correction_ms) > 0
        else ""
    )
    print(
        f"\nprocess CPU {run.cpu_percent:.0f}% of one core, RSS {run.rss_end_mb:.0f} MB, "
        f"growth after warm-up {run.rss_growth_mb:+.1f} MB{correction}"
    )
    sys.stdout.flush()


def main() -> int:
    """Run the chosen modes and print their tables."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("modes", nargs="*", help=f"any of {', '.join(MODES)} (default: all)")
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--warmup", type=float, default=5.0)
    parser.add_argument(
        "--switch-interval-ms",
        type=float,
        default=None,
        help="sys.setswitchinterval for this run (Python's default is 5 ms)",
    )
    parser.add_argument(
        "--cv-threads", type=int, default=None, help="cv2.setNumThreads for this run"
    )
    args = parser.parse_args()
    if args.cv_threads is not None:
        cv2.setNumThreads(args.cv_threads)
    unknown = set(args.modes) - set(MODES)
    if unknown:
        parser.error(f"unknown modes {sorted(unknown)}; choose from {', '.join(MODES)}")
    if args.switch_interval_ms is not None:
        sys.setswitchinterval(args.switch_interval_ms / 1000.0)
    app = QApplication.instance() or QApplication(sys.argv)
    assert isinstance(app, QApplication)
    profile = load_profile()
    print(
        f"bench_video: {os.cpu_count()} CPUs, modes {', '.join(args.modes or MODES)}, "
        f"GIL switch interval {sys.getswitchinterval() * 1000:.1f} ms, "
        f"OpenCV threads {cv2.getNumThreads()}"
    )
    for mode in args.modes or MODES:
        report(run_mode(app, profile, mode, args.seconds, args.warmup), profile.link.camera_names)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
