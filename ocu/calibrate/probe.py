"""`ocu probe`: listen to a robot and say, in plain sentences, where it contradicts the profile.

The probe sends only remote-control packets with every axis zero (a robot answers whoever
sent the latest RCP), no extension hellos, and listens for a while. Then it reports what
arrived — datagram sizes and first bytes, rates, which frame types parse, the tick, the
motors, their positions and speeds — and every place where that contradicts the profile,
naming the profile key and whether that key is an assumption. `ProbeReport.ok` is False
when anything contradicts the profile.
"""

from __future__ import annotations

import itertools
import math
import statistics
import struct
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from ocu.calibrate.guard import StopSignal
from ocu.calibrate.observer import Datagram, Sample, TelemetryLog
from ocu.link.base import Link
from ocu.profile import RobotProfile
from ocu.protocol.mapping import ticks_to_rad
from ocu.protocol.packets import (
    JPEG_SOI,
    MOTOR_SIZE,
    MOTOR_SLOTS,
    RCP_SIZE,
    TELEMETRY_HEADER_STRUCT,
    TELEMETRY_SIZE,
)
from ocu.records import SCAN, STATUS, TELEMETRY, VIDEO, VIDEO_FRAGMENT

OK = "ok"
NOTE = "note"
MISMATCH = "mismatch"

DEFAULT_LISTEN_S = 5.0
# The tick rate may differ from the profile's by this fraction before the probe objects.
TICK_RATE_TOLERANCE = 0.25
# Telemetry may come this much slower than the profile says before the probe objects.
SLOW_TELEMETRY_FACTOR = 0.5
# A big-endian tick or position read little-endian is astronomically large.
HUGE_TICK = 2**48
# Pad bytes in a motor record under the assumed layout (docs/protocol.md).
MOTOR_PAD_OFFSETS = (3, 14, 15)
# Datagrams of ocu's protocol extension (docs/protocol.md), which the console's link may get.
EXTENSION_KINDS = frozenset({VIDEO_FRAGMENT, STATUS, SCAN})


@dataclass(frozen=True)
class Finding:
    """One sentence of the report; `key` names the profile key concerned, if any."""

    level: str
    text: str
    key: str | None = None


@dataclass
class ProbeReport:
    """What the probe saw and what it makes of it."""

    address: str
    listened_s: float
    sent: int
    findings: list[Finding] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """Whether nothing contradicts the profile."""
        return not any(f.level == MISMATCH for f in self.findings)

    @property
    def mismatches(self) -> list[Finding]:
        """The findings that contradict the profile."""
        return [f for f in self.findings if f.level == MISMATCH]

    def text(self) -> str:
        """The report as lines for a terminal."""
        marks = {OK: "  ok ", NOTE: " note", MISMATCH: "  !! "}
        lines = [
            f"Probe of {self.address}: listened {self.listened_s:.1f} s, sent {self.sent} "
            "remote-control packets with every axis zero."
        ]
        lines += [f"{marks[f.level]} {f.text}" for f in self.findings]
        verdict = (
            "Everything that arrived matches the profile."
            if self.ok
            else f"{len(self.mismatches)} contradiction(s) with the profile."
        )
        lines.append(verdict)
        return "\n".join(lines)


def run_probe(
    link: Link,
    profile: RobotProfile,
    *,
    listen_s: float = DEFAULT_LISTEN_S,
    stop: StopSignal | None = None,
    progress: Callable[[float], None] | None = None,
) -> ProbeReport:
    """Listen on a started-here link for listen_s and judge what arrived; the link is shut
    down (zeros last) before this returns. The link must be new: it is started here."""
    log = TelemetryLog(profile.link.telemetry_tick_hz)
    link.subscribe(log)
    started = time.monotonic()
    link.start()
    try:
        while True:
            elapsed = time.monotonic() - started
            if elapsed >= listen_s or (stop is not None and stop.stopped):
                break
            if progress is not None:
                progress(elapsed / listen_s)
            if stop is not None:
                stop.wait(min(0.1, listen_s - elapsed))
            else:
                time.sleep(min(0.1, listen_s - elapsed))
        stats = link.stats()
    finally:
        link.shutdown()
        link.unsubscribe(log)
    listened = time.monotonic() - started
    report = ProbeReport(link.description, listened, stats.sent)
    report.findings = judge(profile, log, listened, foreign=stats.foreign)
    if stop is not None and stop.stopped:
        report.findings.insert(0, Finding(NOTE, f"stopped early: {stop.reason}"))
    return report


def judge(
    profile: RobotProfile,
    log: TelemetryLog,
    listened_s: float,
    *,
    foreign: int,
    commanded_motion: bool = False,
) -> list[Finding]:
    """Every finding about what a telemetry log holds (pure: the tests feed it datagrams).

    `commanded_motion`: the OCU commanded motion while the log filled (the console's Robot
    check), so the motors' speeds are not expected to be zero and are not judged."""
    findings: list[Finding] = []
    datagrams = list(log.datagrams)
    samples = log.samples()
    if not datagrams:
        port_note = _assumed(profile, "link.port")
        findings.append(
            Finding(
                MISMATCH,
                f"Nothing arrived in {listened_s:.1f} s. Check the robot's address, that its "
                f"server runs, and the port (link.port = {profile.link.port}{port_note}).",
                "link.port",
            )
        )
    if foreign:
        findings.append(
            Finding(
                MISMATCH,
                f"{foreign} datagram(s) came from another address or port than the one "
                "the RCPs go to: the robot may answer from another port, or another device "
                "talks to this computer.",
                "link.port",
            )
        )
    findings += _datagram_findings(profile, datagrams)
    if samples:
        findings += _rate_findings(profile, samples, listened_s)
        findings += _motor_findings(profile, samples, judge_speeds=not commanded_motion)
        if commanded_motion:
            findings.append(
                Finding(NOTE, "The console commanded motion meanwhile: speeds are not judged.")
            )
        pads = judge_pads(datagrams, profile.link.frame_types.telemetry)
        if pads is not None:
            findings.append(pads)
    elif datagrams:
        findings.append(
            Finding(MISMATCH, "No telemetry packet could be decoded.", "link.frame_types")
        )
    return findings


def _assumed(profile: RobotProfile, key: str) -> str:
    return ", an assumption" if profile.provenance(key) == "assumption" else ""


def _hex(data: bytes, count: int = 6) -> str:
    return " ".join(f"{b:02x}" for b in data[:count])


def _datagram_findings(profile: RobotProfile, datagrams: Sequence[Datagram]) -> list[Finding]:
    types = profile.link.frame_types
    findings: list[Finding] = []
    groups: Counter[tuple[int, int]] = Counter()
    example: dict[tuple[int, int], Datagram] = {}
    kinds: dict[tuple[int, int], Counter[str]] = {}
    for datagram in datagrams:
        key = (datagram.data[0] if datagram.data else -1, datagram.size)
        # Video frames vary in size: one group per first byte; so do the extension's.
        if datagram.kind == VIDEO or (datagram.data[:1] and datagram.data[0] == types.video):
            key = (key[0], -1)
        elif datagram.kind in EXTENSION_KINDS:
            key = (key[0], -2)
        groups[key] += 1
        example.setdefault(key, datagram)
        kinds.setdefault(key, Counter())[datagram.kind] += 1
    for (first, size), count in sorted(groups.items(), key=lambda item: -item[1]):
        datagram = example[(first, size)]
        parsed = kinds[(first, size)]
        shown = f"0x{first:02x}" if first >= 0 else "nothing (empty)"
        if size == -1:
            sizes = [d.size for d in datagrams if d.data[:1] == bytes([first])]
            if parsed[VIDEO]:
                findings.append(
                    Finding(
                        OK,
                        f"{count} video frame(s) of type {shown}, {min(sizes)}-{max(sizes)} "
                        "bytes, each a JPEG.",
                    )
                )
            else:
                findings.append(
                    Finding(
                        MISMATCH,
                        f"{count} datagram(s) of the video type {shown} do not hold a JPEG "
                        f"(they start {_hex(datagram.data)}): check link.frame_types.video.",
                        "link.frame_types.video",
                    )
                )
            continue
        if size == -2:
            what = ", ".join(sorted(parsed))
            findings.append(
                Finding(
                    OK,
                    f"{count} datagram(s) of ocu's protocol extension ({what}), type {shown}, "
                    "parse.",
                )
            )
            continue
        if parsed[TELEMETRY]:
            findings.append(
                Finding(OK, f"{count} telemetry packet(s): type {shown}, {size} bytes, parse.")
            )
            continue
        findings.append(_unexplained(profile, first, size, count, datagram))
    return findings


def _unexplained(
    profile: RobotProfile, first: int, size: int, count: int, datagram: Datagram
) -> Finding:
    """A group of datagrams that did not parse: the likeliest explanation."""
    types = profile.link.frame_types
    head = _hex(datagram.data)
    what = f"{count} datagram(s) of {size} bytes start {head}"
    if first == types.telemetry and size != TELEMETRY_SIZE:
        diff = size - TELEMETRY_SIZE
        words = {1: "one more", -1: "one less"}.get(
            diff, f"{abs(diff)} {'more' if diff > 0 else 'fewer'}"
        )
        return Finding(
            MISMATCH,
            f"Telemetry (type 0x{first:02x}) arrives as {size} bytes, {words} than the tables "
            f"({TELEMETRY_SIZE}): check the pad layout of the motor record "
            f"(docs/protocol.md, alignment layout{_assumed(profile, 'link.frame_types')}).",
            "link.frame_types.telemetry",
        )
    if first == types.telemetry and size == TELEMETRY_SIZE and len(datagram.data) > 9:
        motor_count = datagram.data[9]
        return Finding(
            MISMATCH,
            f"{what}: the telemetry size and type, but it does not parse (motor count byte "
            f"{motor_count}, at most {MOTOR_SLOTS}): the header layout differs from the tables.",
            "link.frame_types.telemetry",
        )
    if size == TELEMETRY_SIZE:
        return Finding(
            MISMATCH,
            f"{what}: the telemetry size ({TELEMETRY_SIZE} bytes), but not the telemetry type "
            f"0x{types.telemetry:02x}: the telemetry frame type may be 0x{first:02x} "
            f"(link.frame_types.telemetry{_assumed(profile, 'link.frame_types')}).",
            "link.frame_types.telemetry",
        )
    if datagram.data[1:4] == JPEG_SOI:
        return Finding(
            MISMATCH,
            f"{what}: a JPEG after the first byte, but not the video type "
            f"0x{types.video:02x}: the video frame type may be 0x{first:02x} "
            f"(link.frame_types.video{_assumed(profile, 'link.frame_types')}).",
            "link.frame_types.video",
        )
    if size == RCP_SIZE:
        return Finding(
            MISMATCH,
            f"{what}: the size of a remote-control packet; another OCU may be sending to "
            "this computer, or the robot echoes RCPs.",
        )
    return Finding(MISMATCH, f"{what}: nothing in the profile explains them.")


def _rate_findings(
    profile: RobotProfile, samples: Sequence[Sample], listened_s: float
) -> list[Finding]:
    findings: list[Finding] = []
    expected_hz = profile.link.telemetry_rate_hz
    times = [s.received_at for s in samples]
    rate_hz = (len(times) - 1) / (times[-1] - times[0]) if len(times) > 1 else 0.0
    if len(times) < 2:
        findings.append(
            Finding(
                NOTE,
                f"Only one telemetry packet in {listened_s:.1f} s: too few to measure the rate "
                "(listen longer).",
            )
        )
    elif rate_hz < SLOW_TELEMETRY_FACTOR * expected_hz:
        findings.append(
            Finding(
                MISMATCH,
                f"Telemetry arrives {rate_hz:.2f} times a second; the profile expects "
                f"{expected_hz:g} (link.telemetry_rate_hz): packets are lost, or the robot "
                "sends less often.",
                "link.telemetry_rate_hz",
            )
        )
    else:
        findings.append(
            Finding(
                OK,
                f"Telemetry arrives {rate_hz:.2f} times a second (the profile says "
                f"{expected_hz:g}).",
            )
        )
    ticks = [s.tick for s in samples]
    if any(b <= a for a, b in itertools.pairwise(ticks)):
        findings.append(Finding(MISMATCH, "The telemetry tick does not always increase."))
    if ticks[-1] >= HUGE_TICK:
        swapped = struct.unpack(">Q", struct.pack("<Q", ticks[-1]))[0]
        findings.append(
            Finding(
                MISMATCH,
                f"The tick reads {ticks[-1]}, an uptime of millennia; read big-endian it is "
                f"{swapped}: the byte order may be big-endian (docs/protocol.md).",
                "link.telemetry_tick_hz",
            )
        )
    elif len(samples) > 2 and times[-1] - times[0] > 1.5:
        tick_hz = (ticks[-1] - ticks[0]) / (samples[-1].received_at - samples[0].received_at)
        configured = profile.link.telemetry_tick_hz
        if abs(tick_hz / configured - 1.0) > TICK_RATE_TOLERANCE:
            findings.append(
                Finding(
                    MISMATCH,
                    f"The tick advances about {tick_hz:.0f} per second; the profile says "
                    f"{configured:g} (link.telemetry_tick_hz"
                    f"{_assumed(profile, 'link.telemetry_tick_hz')}).",
                    "link.telemetry_tick_hz",
                )
            )
        else:
            findings.append(Finding(OK, f"The tick increases, about {tick_hz:.0f} per second."))
    return findings


def _motor_findings(
    profile: RobotProfile, samples: Sequence[Sample], *, judge_speeds: bool = True
) -> list[Finding]:
    findings: list[Finding] = []
    latest = samples[-1]
    counts = {len(s.motors) for s in samples}
    seen = set().union(*(s.motors.keys() for s in samples))
    known = {m.device_id: m for m in profile.motors.values()}
    findings.append(
        Finding(
            OK if max(counts) <= MOTOR_SLOTS else MISMATCH,
            f"{max(counts)} motor record(s) per packet, devices {sorted(seen)}.",
        )
    )
    for device_id in sorted(seen - known.keys()):
        findings.append(
            Finding(
                MISMATCH,
                f"Device {device_id} reports, but no motor of the profile has that ID "
                f"(motors.*.device_id{_assumed(profile, 'motors.*.device_id')}).",
                "motors.*.device_id",
            )
        )
    for device_id in sorted(known.keys() - seen):
        name = known[device_id].name
        findings.append(
            Finding(
                MISMATCH,
                f"The profile's {name} (device {device_id}) never reports.",
                f"motors.{name}.device_id",
            )
        )
    states = Counter((r.state, r.mode) for r in latest.motors.values())
    findings.append(
        Finding(
            NOTE,
            "Device state / operation mode seen: "
            + ", ".join(f"{s}/{m} on {n}" for (s, m), n in states.most_common())
            + " (their meaning is not documented).",
        )
    )
    speed_scale = profile.telemetry_speed_per_rad_s
    inside: list[str] = []
    for device_id, record in sorted(latest.motors.items()):
        motor = known.get(device_id)
        if motor is None:
            continue
        moving = [s.motors[device_id].speed for s in samples if device_id in s.motors]
        fastest = max(moving, key=abs)
        if fastest != 0 and judge_speeds:
            findings.append(
                Finding(
                    MISMATCH,
                    f"The {motor.name} reports a speed of {fastest / speed_scale:.3f} "
                    f"(raw {fastest}) while every axis is zero: another client may command "
                    "the robot, or the speed unit is not the profile's "
                    "(si.telemetry_speed_per_rad_s).",
                    "si.telemetry_speed_per_rad_s",
                )
            )
        if not motor.has_position or motor.limits_rad is None or motor.limits_deg is None:
            if record.position != 0 and motor.track is not None:
                findings.append(
                    Finding(
                        NOTE,
                        f"The {motor.name} reports a position (raw {record.position}); the "
                        "documents say the tracks report none.",
                    )
                )
            continue
        angle_deg = math.degrees(ticks_to_rad(motor, record.position))
        low, high = motor.limits_deg
        if low <= angle_deg <= high:
            inside.append(f"{motor.name} {angle_deg:.1f}°")
            continue
        key = f"motors.{motor.name}"
        swapped = struct.unpack(">I", struct.pack("<I", record.position))[0]
        findings.append(
            Finding(
                MISMATCH,
                f"The {motor.name} reads {angle_deg:.1f}° (raw {record.position}, "
                f"0x{record.position:08x}), outside its limits [{low:g}°, {high:g}°]: "
                f"{key}.zero_offset_ticks ({motor.zero_offset_ticks}) or {key}.ticks_per_rad "
                f"is wrong{_assumed(profile, key + '.zero_offset_ticks')}, or the encoder "
                f"reports nothing (read big-endian the raw value is {swapped}). "
                "`ocu calibrate` measures both.",
                f"{key}.zero_offset_ticks",
            )
        )
    if inside:
        findings.append(
            Finding(OK, "Positions inside the profile's limits: " + ", ".join(inside) + ".")
        )
    return findings


def judge_pads(datagrams: Sequence[Datagram], telemetry_type: int) -> Finding | None:
    """Whether the pad bytes of the motor records are zero, as the assumed layout has them."""
    header = TELEMETRY_HEADER_STRUCT.size
    nonzero = 0
    checked = 0
    for datagram in datagrams:
        data = datagram.data
        if datagram.kind != TELEMETRY or len(data) != TELEMETRY_SIZE or data[0] != telemetry_type:
            continue
        count = min(data[header - 1], MOTOR_SLOTS)
        for slot in range(count):
            base = header + slot * MOTOR_SIZE
            checked += 1
            if any(data[base + offset] for offset in MOTOR_PAD_OFFSETS):
                nonzero += 1
    if not checked:
        return None
    if nonzero:
        return Finding(
            MISMATCH,
            f"{nonzero} of {checked} motor records have non-zero pad bytes: the record may be "
            "packed without padding (docs/protocol.md, alignment layout, an assumption).",
        )
    return Finding(OK, f"The pad bytes of {checked} motor records are zero, as assumed.")


def median_interval_s(samples: Sequence[Sample]) -> float | None:
    """The median time between telemetry packets as they arrived."""
    times = [s.received_at for s in samples]
    gaps = [b - a for a, b in itertools.pairwise(times) if b > a]
    return statistics.median(gaps) if gaps else None
