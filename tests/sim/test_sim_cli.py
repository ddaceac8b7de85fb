"""The ocu-sim command line: argument checks in process, a full run as a subprocess."""

from __future__ import annotations

import re
import selectors
import signal
import socket
import subprocess
import sys
import time
from typing import IO

import pytest

from ocu.profile import RobotProfile, load_profile
from ocu.protocol import TelemetryPacket
from ocu.protocol.mapping import CommandMapper
from ocu.protocol.wire import make_codec
from ocu.records import Command
from ocu.sim.cli import build_parser, main

STARTUP_S = 20.0
RECEIVE_S = 5.0
QUIET_S = 0.5
LISTENING = re.compile(r"ocu-sim listening on (?P<host>[\d.]+):(?P<port>\d+)")


@pytest.fixture(scope="module")
def profile() -> RobotProfile:
    """The shipped Engineer profile."""
    return load_profile()


@pytest.mark.parametrize(
    "argv",
    [
        ["--loss", "1.5"],
        ["--loss", "-0.1"],
        ["--duplicate", "2"],
        ["--latency-ms", "-1"],
        ["--jitter-ms", "nan"],
        ["--video-size", "320"],
        ["--video-size", "8x8"],
        ["--video-size", "axb"],
        ["--telemetry-hz", "0"],
        ["--video-fps", "-5"],
        ["--port", "70000"],
        ["--log-level", "LOUD"],
        ["--profile", "/nonexistent/robot.toml"],
        ["--noise-deg", "-1"],
        ["--raw-position", "shoulder"],
        ["--raw-position", "shoulder=4294967296"],
        ["--port", "0", "--raw-position", "nose=0"],
    ],
)
def test_bad_values_are_argparse_errors(
    argv: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    assert "error:" in capsys.readouterr().err


def test_defaults(profile: RobotProfile) -> None:
    args = build_parser().parse_args([])
    assert args.host == "127.0.0.1"
    assert args.port is None  # main() falls back to profile.link.port
    assert args.telemetry_hz is None  # the simulator falls back to the profile's rate
    assert args.video_fps == 10.0
    assert args.video_size == (320, 240)
    args = build_parser().parse_args(["--video-size", "640X480", "--log-level", "debug"])
    assert args.video_size == (640, 480)
    assert args.log_level == "DEBUG"
    args = build_parser().parse_args(
        ["--noise-deg", "0.5", "--raw-position", "shoulder=0xFFFFFFFF"]
    )
    assert args.noise_deg == 0.5
    assert args.raw_position == [("shoulder", 0xFFFFFFFF)]


def _read_line(stream: IO[str] | None, timeout_s: float) -> str:
    """One stdout line of the child, or fail after timeout_s."""
    assert stream is not None
    with selectors.DefaultSelector() as selector:
        selector.register(stream, selectors.EVENT_READ)
        assert selector.select(timeout_s), "ocu-sim printed nothing"
    return stream.readline()


def _receive_telemetry(sock: socket.socket, profile: RobotProfile, timeout_s: float) -> bool:
    """Whether a telemetry packet arrives within timeout_s."""
    codec = make_codec(profile)
    deadline_s = time.monotonic() + timeout_s
    while (remaining_s := deadline_s - time.monotonic()) > 0.0:
        sock.settimeout(remaining_s)
        try:
            data = sock.recv(70_000)
        except TimeoutError:
            return False
        if isinstance(codec.decode(data), TelemetryPacket):
            return True
    return False


def _wait_for_silence(sock: socket.socket, quiet_s: float, timeout_s: float) -> bool:
    """Whether, within timeout_s, nothing arrives for quiet_s in a row."""
    deadline_s = time.monotonic() + timeout_s
    sock.settimeout(quiet_s)
    while time.monotonic() < deadline_s:
        try:
            sock.recv(70_000)
        except TimeoutError:
            return True
    return False


def test_subprocess_serves_telemetry_cuts_restores_and_exits_cleanly(
    profile: RobotProfile,
) -> None:
    telemetry_hz = 20.0
    command = [
        sys.executable,
        "-m",
        "ocu.sim",
        "--port",
        "0",
        "--telemetry-hz",
        str(telemetry_hz),
        "--video-fps",
        "0",
    ]
    with subprocess.Popen(
        command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    ) as process:
        try:
            line = _read_line(process.stdout, STARTUP_S)
            match = LISTENING.fullmatch(line.strip())
            assert match, f"unexpected first line {line!r}"
            address = (match["host"], int(match["port"]))
            assert address[1] != 0
            rcp = make_codec(profile).encode(CommandMapper(profile).to_packet(Command()))
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
                sock.bind(("127.0.0.1", 0))
                sock.sendto(rcp, address)
                assert _receive_telemetry(sock, profile, RECEIVE_S)

                process.send_signal(signal.SIGUSR1)
                # Telemetry at 20 Hz never pauses for 0.5 s unless the link is cut.
                assert _wait_for_silence(sock, QUIET_S, RECEIVE_S)

                process.send_signal(signal.SIGUSR2)
                assert _receive_telemetry(sock, profile, RECEIVE_S)

            process.send_signal(signal.SIGTERM)
            _, stderr = process.communicate(timeout=RECEIVE_S * 2)
            assert process.returncode == 0, stderr
            assert "link cut" in stderr
            assert "link restored" in stderr
            assert "new client" in stderr
        finally:
            if process.poll() is None:
                process.kill()
                process.communicate()
