"""The input mux: which input source may command a channel, and what stops it (twist_mux's
table, for every source of the console).

The rules are data: the Markdown table `mux.md` beside this module (shown in
docs/console.md, "Who commands a channel"), read once at import. A row per source:

- **kind**: `manual` (the operator's own hands: sliders, typed values, keys, switches, the
  pad), `automatic` (started by the operator and run by the control thread: position
  targets, the arm's moves and jogs, the assisted modes, click-to-track) or `planner` (a
  program: ROS, a remote client).
- **priority**: a source takes a channel that is free, its own, or held by a source of a
  lower priority; of the same priority only when it is manual (the latest manual input
  wins); never one of a higher priority. So a planner yields a channel to anything the
  operator does and never takes one back from it.
- **timeout**: what keeps the source alive, the source stops without it: `gui` (the GUI
  thread's heartbeat: the control thread stops these sources when the GUI is silent,
  ocu.core.manager), `pad` (the pad's poll thread: its own stall watch, ocu.gamepad),
  `ros` (the bridge's cmd_vel timeout, ocu.ros), a number of seconds (the model stops the
  source that long after its last input), or `-` (the source ends by itself, or is run by
  the control thread itself).
- **any operator input** (a motion input of the operator on any channel): `wins` for the
  manual sources (it is one); for the others what it does to them, written as for a lock.
  Whatever this column says, an automatic source or a planner yields a channel to manual
  input on that channel (the priorities).
- **locks** (`focus lost`, `GUI silent`, `LINK LOST`, `robot stop` - the robot's own
  controller refuses motion, a UR's protective stop -, `e-stop`): `stops`, `keeps`, or
  `keeps if <condition>` - a condition the model evaluates when the lock comes
  (`background`: the pad's mapping lets it drive in the background, docs/gamepad.md;
  `external`: the assisted mode was started by a planner; `a move`: the arm moves to a goal,
  `a jog`: it jogs under the operator's keys). Nothing resumes by itself after a lock: a
  stopped source needs new input. The e-stop, robot stop and LINK LOST columns must say
  `stops` for every source; the table is refused otherwise.

A new source is one file (its input and its stop, calling `ConsoleModel.set_source_velocities`)
plus one registration line (`Source.define` and `model.mux.register`) and its row here.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

TABLE_PATH = Path(__file__).with_name("mux.md")

KINDS = ("manual", "automatic", "planner")
LOCKS = ("focus lost", "GUI silent", "LINK LOST", "robot stop", "e-stop")
OPERATOR = "any operator input"
# Locks every source must stop for (the safety rules: README, docs/console.md "Stopping").
HARD_LOCKS = ("LINK LOST", "robot stop", "e-stop")
CONDITIONS = ("background", "external", "a move", "a jog")
FEEDERS = ("gui", "pad", "ros", "-")
COLUMNS = ("source", "kind", "priority", "timeout", OPERATOR, *LOCKS)


class MuxError(ValueError):
    """The mux table is malformed (the message names the file, the row and the column)."""


@dataclass(frozen=True)
class SourceRule:
    """One row of the table."""

    source: str
    kind: str
    priority: int
    # `gui`, `pad`, `ros`, `-`, or None with `timeout_s` set (seconds after the last input).
    feeder: str | None
    timeout_s: float | None
    # (lock or OPERATOR, "stops" | "keeps" | "keeps if <condition>"; "wins" for OPERATOR
    # when the source is manual)
    locks: tuple[tuple[str, str], ...]

    @property
    def manual(self) -> bool:
        """Whether the source is the operator's own hands."""
        return self.kind == "manual"

    def on_lock(self, lock: str) -> str:
        """What the source does when `lock` comes: stops, keeps, keeps if <condition>."""
        return dict(self.locks)[lock]


Stop = Callable[[str], object]


class InputMux:
    """The table's rules, and each source's stop (registered by the model that runs it)."""

    def __init__(self, rules: tuple[SourceRule, ...], origin: str = "the mux table") -> None:
        self.origin = origin
        self._rules = {rule.source: rule for rule in rules}
        self._order = tuple(rule.source for rule in rules)
        self._stops: dict[str, Stop] = {}

    @classmethod
    def shipped(cls) -> InputMux:
        """The table shipped beside this module (read anew: each model registers its own)."""
        return cls(_SHIPPED, str(TABLE_PATH))

    @classmethod
    def from_text(cls, text: str, origin: str) -> InputMux:
        """A table from Markdown text; MuxError naming `origin`, the row and the column."""
        return cls(parse_table(text, origin), origin)

    # ---- the table -----------------------------------------------------------------------

    def rule(self, source: str) -> SourceRule:
        """The row of a source; MuxError if the table has none."""
        try:
            return self._rules[source]
        except KeyError:
            raise MuxError(f"{self.origin}: no row for the source {source!r}") from None

    @property
    def sources(self) -> tuple[str, ...]:
        """Every source, in the table's order."""
        return self._order

    def __iter__(self) -> Iterator[SourceRule]:
        return (self._rules[name] for name in self._order)

    def may_take(self, source: str, holder: str) -> bool:
        """Whether `source` may command a channel `holder` commands now ("none": nobody)."""
        if holder in ("none", source):
            return True
        wanted, held = self.rule(source), self.rule(holder)
        if wanted.priority != held.priority:
            return wanted.priority > held.priority
        return wanted.manual

    def stopped_by(self, lock: str, conditions: Callable[[str, str], bool]) -> list[str]:
        """The sources `lock` (or OPERATOR: any operator motion input) stops, in the table's
        order; `conditions(source, condition)` says whether a `keeps if <condition>` holds."""
        if lock not in (*LOCKS, OPERATOR):
            raise MuxError(f"{self.origin}: no lock {lock!r} (locks: {', '.join(LOCKS)})")
        stopped = []
        for rule in self:
            action = rule.on_lock(lock)
            if action in ("keeps", "wins"):
                continue
            if action.startswith("keeps if ") and conditions(rule.source, action[9:]):
                continue
            stopped.append(rule.source)
        return stopped

    def fed_by(self, feeder: str) -> list[str]:
        """The sources kept alive by `feeder` (gui, pad, ros)."""
        return [rule.source for rule in self if rule.feeder == feeder]

    def timed(self) -> list[tuple[str, float]]:
        """The sources with a timeout in seconds after their last input."""
        return [(r.source, r.timeout_s) for r in self if r.timeout_s is not None]

    # ---- the sources' stops --------------------------------------------------------------

    def register(self, source: str, stop: Stop) -> None:
        """How a source stops (`stop(reason)`); MuxError if the table has no row for it."""
        self.rule(source)
        self._stops[source] = stop

    def missing(self) -> list[str]:
        """Sources of the table nobody registered a stop for."""
        return [name for name in self._order if name not in self._stops]

    def stop(self, source: str, reason: str) -> bool:
        """Stop one source by its registered stop; False if it has none (the caller zeroes
        the channels it holds)."""
        stop = self._stops.get(source)
        if stop is None:
            return False
        stop(reason)
        return True


def parse_table(text: str, origin: str) -> tuple[SourceRule, ...]:
    """The rules of a Markdown table; MuxError naming `origin`, the row and the column."""
    lines = [line.strip() for line in text.splitlines() if line.strip().startswith("|")]
    if len(lines) < 3:
        raise MuxError(f"{origin}: no table (a header, a separator and a row per source)")
    header = _cells(lines[0])
    if tuple(header) != COLUMNS:
        raise MuxError(f"{origin}: the columns must be {' | '.join(COLUMNS)}, got {header}")
    rules: list[SourceRule] = []
    for number, line in enumerate(lines[2:], start=3):
        cells = _cells(line)
        where = f"{origin}, table row {number - 2}"
        if len(cells) != len(COLUMNS):
            raise MuxError(f"{where}: {len(cells)} cells, the table has {len(COLUMNS)} columns")
        row = dict(zip(COLUMNS, cells, strict=True))
        source = row["source"]
        where = f"{origin}, source {source!r}"
        if not source.isidentifier() or source == "none":
            raise MuxError(f"{where}: a source is a lower-case name, not {source!r}")
        if any(rule.source == source for rule in rules):
            raise MuxError(f"{where}: a second row for the same source")
        rules.append(_rule(row, where))
    return tuple(rules)


def _cells(line: str) -> list[str]:
    return [cell.strip() for cell in line.strip().strip("|").split("|")]


def _rule(row: dict[str, str], where: str) -> SourceRule:
    kind = row["kind"]
    if kind not in KINDS:
        raise MuxError(f"{where}, column kind: one of {', '.join(KINDS)}, not {kind!r}")
    try:
        priority = int(row["priority"])
    except ValueError:
        wrong = row["priority"]
        raise MuxError(f"{where}, column priority: a whole number, not {wrong!r}") from None
    timeout = row["timeout"]
    feeder: str | None = timeout
    timeout_s: float | None = None
    if timeout not in FEEDERS:
        try:
            timeout_s = float(timeout)
        except ValueError:
            timeout_s = math.nan
        if not (math.isfinite(timeout_s) and timeout_s > 0.0):
            raise MuxError(
                f"{where}, column timeout: {', '.join(FEEDERS)} or seconds > 0, not {timeout!r}"
            )
        feeder = None
    locks = []
    for lock in (OPERATOR, *LOCKS):
        action = row[lock]
        if lock == OPERATOR and (kind == "manual" or action == "wins"):
            if (kind == "manual") != (action == "wins"):
                raise MuxError(
                    f"{where}, column {lock}: wins for a manual source and only for one, "
                    f"not {action!r}"
                )
            locks.append((lock, action))
            continue
        if lock in HARD_LOCKS and action != "stops":
            raise MuxError(f"{where}, column {lock}: every source stops, not {action!r}")
        valid = action in ("stops", "keeps") or (
            action.startswith("keeps if ") and action[9:] in CONDITIONS
        )
        if not valid:
            raise MuxError(
                f"{where}, column {lock}: stops, keeps or keeps if "
                f"<{' | '.join(CONDITIONS)}>, not {action!r}"
            )
        locks.append((lock, action))
    return SourceRule(
        source=row["source"],
        kind=kind,
        priority=priority,
        feeder=feeder,
        timeout_s=timeout_s,
        locks=tuple(locks),
    )


_SHIPPED = parse_table(TABLE_PATH.read_text(encoding="utf-8"), str(TABLE_PATH))
