"""The console's settings file (`ocu.ini`, the window layout) and its folder, checked first.

A config directory that is a file, or below one, is a mistake the operator must fix: refused
with the reason. One that cannot be written (read-only, not ours) costs only the layout: the
console runs and says it will not save it. An `ocu.ini` that cannot be read (not an INI file,
not text) is never written over: it is moved aside, and the console says where to.
"""

from __future__ import annotations

import errno
import os
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

SETTINGS_FILE = "ocu.ini"
UNREADABLE_SUFFIX = ".unreadable"


class ConfigDirError(Exception):
    """The config directory cannot be one (a file, or below a file)."""


@dataclass(frozen=True)
class SettingsStatus:
    """Whether the settings may be saved, and what the operator should be told."""

    path: Path
    writable: bool = True
    notes: tuple[str, ...] = ()


def ini_problem(path: Path) -> str | None:
    """Why an existing settings file cannot be read as an INI file (None: it can, or is absent)."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return None
    except OSError as err:
        return f"cannot read it: {err.strerror or err}"
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        return "not text (not UTF-8)"
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line[0] in ";#" or (line[0] == "[" and line.endswith("]")) or "=" in line:
            continue
        return f"line {number} is not an INI line: {line[:40]!r}"
    return None


def _can_write_in(folder: Path) -> str | None:
    """Why no file can be written in `folder` (None: one can)."""
    try:
        with tempfile.TemporaryFile(dir=folder, prefix=".ocu-write-test."):
            pass
    except OSError as err:
        return err.strerror or str(err)
    return None


def config_dir_problem(config_dir: Path) -> str | None:
    """Why this path cannot be a config directory at all (None: it can); changes nothing."""
    if config_dir.exists() and not config_dir.is_dir():
        return f"config directory {config_dir} is a file, not a folder"
    blocker = next((p for p in config_dir.parents if p.exists() and not p.is_dir()), None)
    if blocker is not None:
        return f"config directory {config_dir} cannot be made: {blocker} is a file"
    return None


def prepare_settings(config_dir: Path) -> SettingsStatus:
    """Make the config directory if needed and check its settings file; ConfigDirError if the
    directory cannot be one. An unreadable settings file is moved aside."""
    path = config_dir / SETTINGS_FILE
    problem = config_dir_problem(config_dir)
    if problem is not None:
        raise ConfigDirError(problem)
    try:
        config_dir.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        if err.errno not in (errno.EACCES, errno.EPERM, errno.EROFS):
            raise ConfigDirError(
                f"config directory {config_dir} cannot be made: {err.strerror or err}"
            ) from err
        return SettingsStatus(
            path,
            writable=False,
            notes=(
                f"config directory {config_dir} cannot be made ({err.strerror}): the window "
                "layout is not saved this session",
            ),
        )
    notes: list[str] = []
    writable = True
    problem = ini_problem(path)
    if problem is not None:
        aside = path.with_name(SETTINGS_FILE + UNREADABLE_SUFFIX)
        if aside.exists():
            aside = path.with_name(f"{SETTINGS_FILE}.{time.strftime('%Y%m%d-%H%M%S')}")
            aside = aside.with_name(aside.name + UNREADABLE_SUFFIX)
        try:
            os.replace(path, aside)
        except OSError as err:
            writable = False
            notes.append(
                f"{path} cannot be read ({problem}) nor moved aside ({err.strerror}): it is "
                "left as it is, and the window layout is not saved this session"
            )
        else:
            notes.append(
                f"{path} cannot be read ({problem}): kept as {aside.name}; the window layout "
                "starts from the default"
            )
    if writable:
        why = _can_write_in(config_dir)
        if why is None and path.exists() and not os.access(path, os.W_OK):
            why = f"{SETTINGS_FILE} is read-only"
        if why is not None:
            writable = False
            notes.append(
                f"config directory {config_dir} cannot be written ({why}): the window layout "
                "is not saved this session"
            )
    return SettingsStatus(path, writable, tuple(notes))
