"""Writing a profile's TOML document back (ocu calibrate, ocu-sim --scramble): keys and values
formatted as the shipped profile writes them, atomically."""

from __future__ import annotations

import datetime as dt
import json
import math
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ocu.files import write_text_atomically
from ocu.profile.keys import BARE_KEY, TOML_LINE_LENGTH, ProfileError
from ocu.profile.parse import parse_profile


def _toml_key(key: str) -> str:
    return key if BARE_KEY.match(key) else _toml_string(key)


def _toml_string(text: str) -> str:
    # A JSON string is a TOML basic string; TOML also wants DEL (U+007F) escaped.
    return json.dumps(text, ensure_ascii=False).replace("\x7f", "\\u007f")


def _toml_value(value: Any, where: str) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ProfileError(f"{where}: cannot write {value!r}")
        return repr(value)
    if isinstance(value, str):
        return _toml_string(value)
    if isinstance(value, dt.datetime):
        if value.tzinfo is None:
            raise ProfileError(f"{where}: a date and time needs its offset")
        return value.isoformat()
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v, where) for v in value) + "]"
    raise ProfileError(f"{where}: cannot write a {type(value).__name__}")


def _toml_table(lines: list[str], path: list[str], table: Mapping[str, Any]) -> None:
    values = {k: v for k, v in table.items() if not isinstance(v, dict)}
    tables = {k: v for k, v in table.items() if isinstance(v, dict)}
    if path and (values or not tables):
        lines.append("")
        lines.append("[" + ".".join(_toml_key(part) for part in path) + "]")
    for key, value in values.items():
        where = ".".join([*path, key])
        line = f"{_toml_key(key)} = {_toml_value(value, where)}"
        if isinstance(value, (list, tuple)) and len(line) > TOML_LINE_LENGTH:
            items = [f"    {_toml_value(item, where)}," for item in value]
            line = "\n".join([f"{_toml_key(key)} = [", *items, "]"])
        lines.append(line)
    for key, sub in tables.items():
        _toml_table(lines, [*path, key], sub)


def profile_to_toml(data: Mapping[str, Any], header: str = "") -> str:
    """A profile document as TOML text (comments: the header's lines), which tomllib reads
    back to the same document."""
    lines = [f"# {line}".rstrip() for line in header.splitlines()]
    _toml_table(lines, [], data)
    return "\n".join(lines).lstrip("\n") + "\n"


def write_profile_data(path: str | Path, data: Mapping[str, Any], header: str = "") -> None:
    """Validate a profile document and write it atomically (a temp file renamed over path).

    A profile that does not load is refused before anything is written; a writer killed
    half-way leaves the old file (or none), never half of the new one.
    """
    target = Path(path)
    text = profile_to_toml(data, header)
    parse_profile(tomllib.loads(text), source=str(target))
    write_text_atomically(target, text)
