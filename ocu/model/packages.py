"""Find a ROS package's folder by name, as ROS does, for `package://NAME/...` mesh paths.

ROS resolves `package://NAME` to the folder of the package called NAME: a folder holding a
`package.xml` whose `<name>` is NAME (rospack crawls `ROS_PACKAGE_PATH` for them; ament looks
in `<prefix>/share/NAME` for each prefix of `AMENT_PREFIX_PATH`). A URDF read outside a ROS
workspace usually sits inside its package, so the folders above it are searched too, however
far up the package's root is. Places searched, in order:

1. the URDF's folder and every folder above it: the folder itself when its `package.xml`
   names the package or the folder has the package's name, and a sub-folder of that name
   (or whose `package.xml` names it);
2. roots the user names (`--package-path DIR`, or the `OCU_PACKAGE_PATH` variable, a list
   like `PATH`), then `ROS_PACKAGE_PATH`: each crawled for the package, as rospack does;
3. `AMENT_PREFIX_PATH`: `<prefix>/share/NAME`.
"""

from __future__ import annotations

import argparse
import functools
import os
import re
from collections.abc import Iterator, Sequence
from pathlib import Path

PACKAGE_PATH_VARIABLE = "OCU_PACKAGE_PATH"
# How deep below a root the crawl looks for package.xml files (rospack has no limit; a limit
# keeps a root such as / or $HOME from being read whole).
_CRAWL_DEPTH = 6
_NAME = re.compile(rb"<name>\s*([^<\s]+)\s*</name>")


def package_xml_name(folder: Path) -> str | None:
    """The `<name>` in the folder's package.xml, or None without one."""
    try:
        head = (folder / "package.xml").read_bytes()[:4096]
    except OSError:
        return None
    match = _NAME.search(head)
    return match.group(1).decode("utf-8", "replace") if match else None


def _children_named(folder: Path, name: str) -> list[Path]:
    """Sub-folders whose package.xml names the package (a package in a folder of another
    name, e.g. a repository's checkout)."""
    try:
        children = [p for p in folder.iterdir() if p.is_dir() and p.name != name]
    except OSError:
        return []
    return sorted(p for p in children if package_xml_name(p) == name)


def _is_package(folder: Path, name: str) -> bool:
    return folder.name == name or package_xml_name(folder) == name


@functools.lru_cache(maxsize=64)
def _crawl(root: str) -> dict[str, tuple[Path, ...]]:
    """Every package below a root (by package.xml name, and by folder name), rospack-like:
    a package's own sub-folders are not searched for more packages."""
    found: dict[str, list[Path]] = {}

    def visit(folder: Path, depth: int) -> None:
        name = package_xml_name(folder)
        if name is not None:
            found.setdefault(name, []).append(folder)
            return
        if depth >= _CRAWL_DEPTH:
            return
        try:
            children = sorted(p for p in folder.iterdir() if p.is_dir())
        except OSError:
            return
        for child in children:
            if child.name.startswith(".") or (child / "CATKIN_IGNORE").exists():
                continue
            found.setdefault(child.name, []).append(child)
            visit(child, depth + 1)

    visit(Path(root), 0)
    return {name: tuple(folders) for name, folders in found.items()}


def _environment_list(variable: str) -> list[Path]:
    return [Path(entry) for entry in os.environ.get(variable, "").split(os.pathsep) if entry]


def package_roots(extra: Sequence[str | Path] = ()) -> list[Path]:
    """The roots crawled for packages: the user's, then `OCU_PACKAGE_PATH`, then
    `ROS_PACKAGE_PATH`."""
    roots = [Path(p) for p in extra]
    roots += _environment_list(PACKAGE_PATH_VARIABLE) + _environment_list("ROS_PACKAGE_PATH")
    return list(dict.fromkeys(roots))


def package_folders(name: str, start: Path, extra: Sequence[str | Path] = ()) -> list[Path]:
    """Folders that may be the package NAME, most likely first (see the module docstring)."""
    environment = tuple(
        os.environ.get(v, "")
        for v in (PACKAGE_PATH_VARIABLE, "ROS_PACKAGE_PATH", "AMENT_PREFIX_PATH")
    )
    return list(_cached_folders(name, start.resolve(), tuple(str(p) for p in extra), environment))


@functools.lru_cache(maxsize=256)
def _cached_folders(
    name: str, start: Path, extra: tuple[str, ...], _environment: tuple[str, ...]
) -> tuple[Path, ...]:
    return tuple(dict.fromkeys(_package_folders(name, start, extra)))


def _package_folders(name: str, start: Path, extra: Sequence[str]) -> Iterator[Path]:
    for folder in (start, *start.parents):
        if _is_package(folder, name):
            yield folder
        if (folder / name).is_dir():
            yield folder / name
        yield from _children_named(folder, name)
    for root in package_roots(extra):
        if _is_package(root, name):
            yield root
        yield from _crawl(str(root)).get(name, ())
    for prefix in _environment_list("AMENT_PREFIX_PATH"):
        yield prefix / "share" / name


def add_package_path_option(parser: argparse.ArgumentParser) -> None:
    """`--package-path DIR` (repeatable): folders searched for `package://` packages."""
    parser.add_argument(
        "--package-path",
        action="append",
        type=Path,
        default=[],
        metavar="DIR",
        help=f"a folder holding ROS packages named by package:// mesh paths (repeatable; "
        f"also {PACKAGE_PATH_VARIABLE}, ROS_PACKAGE_PATH, AMENT_PREFIX_PATH)",
    )
