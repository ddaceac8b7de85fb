"""`ocu urdf-check FOLDER ...`: load every URDF under the folders and say what happened.

For each file: loaded (links, moving joints, triangles, and whether the collision geometry
is drawn), what warned and why (each warning with its line), what loads but draws nothing,
and what failed (the reason). The exit status is 0 when every file loaded with something to
draw, 1 otherwise. Neither Qt nor OpenGL is needed: this is the loader the 3D view and
`ocu screenshot` use, run on its own.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

from ocu.model.packages import add_package_path_option
from ocu.model.urdf import RobotModel, UrdfError, load_urdf

SUFFIXES = (".urdf", ".URDF")


@dataclass(frozen=True)
class CheckResult:
    """What loading one URDF gave."""

    path: Path
    model: RobotModel | None
    error: str | None
    seconds: float

    @property
    def status(self) -> str:
        """'failed', 'empty' (loads, draws nothing), 'warned' or 'loaded'."""
        if self.model is None:
            return "failed"
        if self.model.triangle_count == 0:
            return "empty"
        return "warned" if self.model.warnings else "loaded"


def find_urdfs(paths: Iterable[Path]) -> list[Path]:
    """URDF files: the files given, and every *.urdf below the folders given."""
    found: list[Path] = []
    for path in paths:
        if path.is_dir():
            found.extend(sorted(p for p in path.rglob("*") if p.suffix in SUFFIXES))
        else:
            found.append(path)
    return list(dict.fromkeys(found))


def check_urdf(path: Path, package_paths: Sequence[Path] = ()) -> CheckResult:
    """Load one URDF and its meshes, as the 3D view would."""
    started = time.perf_counter()
    try:
        model = load_urdf(path, package_paths=package_paths)
    except UrdfError as err:
        return CheckResult(path, None, str(err), time.perf_counter() - started)
    return CheckResult(path, model, None, time.perf_counter() - started)


def _short(message: str, source: str) -> str:
    return message.removeprefix(f"{source}: ")


def report(results: Sequence[CheckResult], out: TextIO, base: Path | None = None) -> None:
    """Print one block per file and a summary line."""
    for result in results:
        name = str(result.path.relative_to(base)) if base else str(result.path)
        model = result.model
        if model is None:
            print(f"FAILED  {name}: {_short(result.error or '', str(result.path))}", file=out)
            continue
        drawn = ", drawn from its collision geometry" if model.drawn_from_collision else ""
        label = {"empty": "EMPTY ", "warned": "warned", "loaded": "loaded"}[result.status]
        print(
            f"{label}  {name}: {len(model.meshes)} links, "
            f"{len(model.tree.actuated_joints)} moving joints, "
            f"{model.triangle_count} triangles{drawn} ({result.seconds * 1000:.0f} ms)",
            file=out,
        )
        if result.status == "empty":
            print("        nothing to draw: no link has triangles", file=out)
        for warning in model.warnings:
            print(f"        - {_short(warning, str(result.path))}", file=out)
    counts = {s: sum(r.status == s for r in results) for s in ("loaded", "warned", "empty")}
    failed = sum(r.status == "failed" for r in results)
    print(
        f"{len(results)} URDF files: {counts['loaded']} loaded cleanly, {counts['warned']} "
        f"loaded with warnings, {counts['empty']} loaded with nothing to draw, {failed} failed",
        file=out,
    )


def build_parser() -> argparse.ArgumentParser:
    """The command line of `ocu urdf-check`."""
    parser = argparse.ArgumentParser(
        prog="ocu urdf-check",
        description="Load every URDF under the given folders (and the files given) as the 3D "
        "view does, and print what loaded, what warned and why, and what failed.",
    )
    parser.add_argument("paths", nargs="+", type=Path, metavar="FOLDER_OR_FILE")
    add_package_path_option(parser)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point; argv are the arguments after `urdf-check`. Returns the exit status."""
    args = build_parser().parse_args(argv)
    missing = [p for p in args.paths if not p.exists()]
    if missing:
        print(f"ocu urdf-check: no such file or folder: {missing[0]}", file=sys.stderr)
        return 2
    files = find_urdfs(args.paths)
    if not files:
        print("ocu urdf-check: no *.urdf files found", file=sys.stderr)
        return 2
    results = [check_urdf(path, args.package_path) for path in files]
    base = args.paths[0] if len(args.paths) == 1 and args.paths[0].is_dir() else None
    report(results, sys.stdout, base)
    return 0 if all(r.status in ("loaded", "warned") for r in results) else 1
