"""The console's scheduling priority: ahead of batch work on the same machine, where allowed.

An operator's key must reach the robot while a compile or a video encode keeps every core
busy. With two CPU-bound processes beside the console on two cores, the console at the
default priority waits for the scheduler at every step of the key's path (the GUI thread, the
model's lock, the link's sender); at nice -10 the same path is scheduled at once
(bench/bench_core.py; the figures are in the README). Audio software does the same (JACK,
PipeWire through rtkit).

Linux keeps the nice value per thread and a new thread starts with its creator's: so
`raise_priority` runs first thing in `ocu` and `ocu-ros`, before Qt, the link or the control
core start a thread, and every thread of the process gets it. Lowering the nice value needs
CAP_SYS_NICE (root) or an `RLIMIT_NICE` allowance (`/etc/security/limits.conf`: `@ocu - nice
-10`); without either the console runs at the priority it was started with and says so. Under
the kernel's autogroup scheduling (most desktops) the nice value orders the threads of one
session; docs/console.md says what that means for jobs started in another terminal.
"""

from __future__ import annotations

import argparse
import logging
import os
import resource
from dataclasses import dataclass

log = logging.getLogger("ocu.core")

#: The nice value `ocu` and `ocu-ros` ask for by default (`--nice`).
DEFAULT_NICE = -10
#: The environment variable that overrides the default (`ocu-ros` reads only this).
NICE_ENV = "OCU_NICE"
NICE_MIN = -20
NICE_MAX = 19


@dataclass(frozen=True)
class Priority:
    """The nice value asked for, the one the process runs at, and why they differ."""

    asked: int
    got: int
    note: str = ""

    @property
    def text(self) -> str:
        """One line for the log and the control timing ("nice -10" ...)."""
        if self.got == self.asked or not self.note:
            return f"nice {self.got}"
        return f"nice {self.got} ({self.note})"


def nice_from_env(default: int = DEFAULT_NICE) -> int:
    """$OCU_NICE when set (ValueError naming it if it is not a nice value), else `default`."""
    text = os.environ.get(NICE_ENV, "").strip()
    if not text:
        return default
    try:
        value = int(text)
    except ValueError:
        raise ValueError(f"${NICE_ENV}: not a whole number: {text!r}") from None
    if not NICE_MIN <= value <= NICE_MAX:
        raise ValueError(f"${NICE_ENV}: {value} is outside {NICE_MIN}..{NICE_MAX}")
    return value


def current_nice() -> int:
    """The calling thread's nice value (Linux: per thread)."""
    return os.getpriority(os.PRIO_PROCESS, 0)


def allowed_nice() -> int:
    """The lowest nice value this process may set without CAP_SYS_NICE (RLIMIT_NICE)."""
    soft, _hard = resource.getrlimit(resource.RLIMIT_NICE)
    if soft == resource.RLIM_INFINITY:
        return NICE_MIN
    # The limit is 20 - nice (1 means 19, 40 means -20); 0 allows no lowering at all.
    return max(NICE_MIN, 20 - int(soft))


def raise_priority(nice: int = DEFAULT_NICE) -> Priority:
    """Run this thread, and every thread it starts from now on, at `nice` where allowed.

    Never raises: without the permission the best allowed value is taken, and if none is
    lower than the current one the priority stays and the note says why. A value above the
    current one (a nicer console) is always allowed.
    """
    if not NICE_MIN <= nice <= NICE_MAX:
        raise ValueError(f"nice must be {NICE_MIN}..{NICE_MAX}, got {nice}")
    now = current_nice()
    if nice == now:
        return Priority(nice, now)
    try:
        os.setpriority(os.PRIO_PROCESS, 0, nice)
        return Priority(nice, current_nice())
    except PermissionError:
        pass
    floor = allowed_nice()
    note = "not permitted: needs CAP_SYS_NICE or an RLIMIT_NICE allowance (docs/console.md)"
    if floor < now:
        try:
            os.setpriority(os.PRIO_PROCESS, 0, floor)
            return Priority(nice, current_nice(), f"RLIMIT_NICE allows {floor}")
        except PermissionError:
            pass
    return Priority(nice, current_nice(), note)


def reset_for_child(argv: list[str]) -> list[str]:
    """`argv` run at the default priority (0) when this process runs below it.

    For a process that stands in for something elsewhere (the built-in simulator is the
    robot): it must not compete with the console at the console's priority.
    """
    now = current_nice()
    if now >= 0:
        return argv
    return ["nice", "-n", str(-now), *argv]


def behind(argv: list[str], steps: int) -> list[str]:
    """`argv` run `steps` nice values behind this process (never ahead of it).

    For a helper of the console's own whose work is not the operator's (the live relay
    serving observers): ahead of batch jobs when the console is raised, behind the console.
    """
    if steps <= 0:
        return argv
    return ["nice", "-n", str(steps), *argv]


def nice_value(text: str) -> int:
    """--nice: a nice value, -20 to 19."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
    if not NICE_MIN <= value <= NICE_MAX:
        raise argparse.ArgumentTypeError(f"{value} is outside {NICE_MIN}..{NICE_MAX}")
    return value
