"""URScript motion commands: the OCU writes them, the simulator parses them (docs/ur.md)."""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass

from ocu.protocol.ur.common import JOINTS, UrProtocolError, Vector6

# ---- URScript motion commands ----------------------------------------------------------------


def _vector(values: Sequence[float], what: str) -> str:
    if len(values) != JOINTS:
        raise UrProtocolError(f"{what} has {len(values)} values, expected {JOINTS}")
    for value in values:
        if not math.isfinite(value):
            raise UrProtocolError(f"{what} holds a non-finite value {value!r}")
    return "[" + ",".join(f"{v:.6f}" for v in values) + "]"


def _number(value: float, what: str, *, positive: bool = False) -> str:
    if not math.isfinite(value) or (positive and value <= 0) or value < 0:
        need = "> 0" if positive else ">= 0"
        raise UrProtocolError(f"{what} must be finite and {need}, got {value!r}")
    return f"{value:.6f}"


def speedj(qd: Sequence[float], a: float, t: float) -> bytes:
    """`speedj(qd, a, t)`: joint speeds (rad/s), acceleration (rad/s²), time to run (s)."""
    return (
        f"speedj({_vector(qd, 'qd')},{_number(a, 'a', positive=True)},{_number(t, 't')})\n"
    ).encode()


def stopj(a: float) -> bytes:
    """`stopj(a)`: decelerate every joint to rest at a (rad/s²)."""
    return f"stopj({_number(a, 'a', positive=True)})\n".encode()


def servoj(q: Sequence[float], t: float, lookahead_time: float = 0.1, gain: float = 300.0) -> bytes:
    """`servoj(q, 0, 0, t, lookahead_time, gain)`: follow a joint position for t seconds."""
    return (
        f"servoj({_vector(q, 'q')},0,0,{_number(t, 't', positive=True)},"
        f"{_number(lookahead_time, 'lookahead_time', positive=True)},"
        f"{_number(gain, 'gain', positive=True)})\n"
    ).encode()


def movej(q: Sequence[float], a: float, v: float) -> bytes:
    """`movej(q, a, v)`: move to joint position q with acceleration a and speed v."""
    return (
        f"movej({_vector(q, 'q')},a={_number(a, 'a', positive=True)},"
        f"v={_number(v, 'v', positive=True)})\n"
    ).encode()


@dataclass(frozen=True)
class ScriptCommand:
    """One URScript motion call as the controller understood it (defaults filled in)."""

    name: str
    q: Vector6 | None = None
    qd: Vector6 | None = None
    a: float = 0.0
    v: float = 0.0
    t: float = 0.0
    lookahead_time: float = 0.1
    gain: float = 300.0


_CALL = re.compile(r"^\s*(?P<name>[a-z_]+)\s*\((?P<args>.*)\)\s*$", re.DOTALL)
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_TOKEN = re.compile(rf"\s*(?:(?P<key>[a-z_]+)\s*=\s*)?(?P<value>\[[^\]]*\]|{_NUMBER})\s*(?:,|$)")
#: Each call's parameters in order, with their defaults (URScript manual; docs/ur.md).
_SIGNATURES: dict[str, tuple[tuple[str, float | None], ...]] = {
    "speedj": (("qd", None), ("a", None), ("t", 0.0)),
    "stopj": (("a", None),),
    "servoj": (
        ("q", None),
        ("a", 0.0),
        ("v", 0.0),
        ("t", 0.002),
        ("lookahead_time", 0.1),
        ("gain", 300.0),
    ),
    "movej": (("q", None), ("a", 1.4), ("v", 1.05), ("t", 0.0), ("r", 0.0)),
}
_VECTORS = {"q", "qd"}


def parse_script_line(line: str) -> ScriptCommand:
    """Parse one URScript line of the subset the simulator runs (speedj, stopj, servoj, movej).

    UrProtocolError for anything else: another function, a pose (p[...]) where joints are
    expected, a wrong count, a non-finite number, a negative time or acceleration.
    """
    match = _CALL.match(line)
    if match is None:
        raise UrProtocolError(f"not a URScript call: {line[:60]!r}")
    name = match["name"]
    signature = _SIGNATURES.get(name)
    if signature is None:
        raise UrProtocolError(f"{name}() is not in the simulator's URScript subset")
    args = match["args"]
    values: dict[str, float | Vector6] = {}
    position = 0
    offset = 0
    params = [p for p, _ in signature]
    while offset < len(args):
        token = _TOKEN.match(args, offset)
        if token is None or token.end() == offset:
            raise UrProtocolError(f"{name}(): cannot read the arguments at {args[offset:][:30]!r}")
        offset = token.end()
        key = token["key"]
        if key is None:
            if values.keys() - set(params[:position]):
                raise UrProtocolError(f"{name}(): a positional argument after a keyword one")
            if position >= len(params):
                raise UrProtocolError(f"{name}() takes at most {len(params)} arguments")
            key = params[position]
            position += 1
        elif key not in params:
            raise UrProtocolError(f"{name}() has no parameter {key!r}")
        elif key in values:
            raise UrProtocolError(f"{name}(): {key} given twice")
        values[key] = _parse_value(name, key, token["value"])
    for param, default in signature:
        if param not in values:
            if default is None:
                raise UrProtocolError(f"{name}(): {param} is required")
            values[param] = default
    scalars = {k: v for k, v in values.items() if isinstance(v, float)}
    for key in ("a", "v", "t", "lookahead_time", "gain"):
        if scalars.get(key, 0.0) < 0:
            raise UrProtocolError(f"{name}(): {key} must be >= 0, got {scalars[key]}")
    if name == "stopj" and scalars["a"] <= 0:
        raise UrProtocolError("stopj(): a must be > 0")
    vector = {k: v for k, v in values.items() if isinstance(v, tuple)}
    return ScriptCommand(
        name=name,
        q=vector.get("q"),
        qd=vector.get("qd"),
        a=scalars.get("a", 0.0),
        v=scalars.get("v", 0.0),
        t=scalars.get("t", 0.0),
        lookahead_time=scalars.get("lookahead_time", 0.1),
        gain=scalars.get("gain", 300.0),
    )


def _parse_value(name: str, key: str, text: str) -> float | Vector6:
    if text.startswith("["):
        if key not in _VECTORS:
            raise UrProtocolError(f"{name}(): {key} is a number, not a list")
        items = [item.strip() for item in text[1:-1].split(",")]
        if len(items) != JOINTS or not all(re.fullmatch(_NUMBER, item) for item in items):
            raise UrProtocolError(f"{name}(): {key} must be a list of {JOINTS} numbers: {text}")
        vector = tuple(float(item) for item in items)
        return (vector[0], vector[1], vector[2], vector[3], vector[4], vector[5])
    if key in _VECTORS:
        raise UrProtocolError(f"{name}(): {key} must be a list of {JOINTS} joint values")
    value = float(text)
    if not math.isfinite(value):
        raise UrProtocolError(f"{name}(): {key} is not finite")
    return value
