"""`--live [HOST:]PORT` and `--live-token`: parsing, the exposure rule, starting the server.

A server binds only the address given, loopback by default. Any other address needs a token
(`--live-token` or $OCU_LIVE_TOKEN; the variable keeps it out of `ps`): the live channels
show the robot's cameras and where it is to whoever connects.
"""

from __future__ import annotations

import argparse
import atexit
import ipaddress
import os
import socket
from collections.abc import Callable
from typing import TYPE_CHECKING, Final, TypeVar

from ocu.link.base import Link
from ocu.profile import RobotProfile

if TYPE_CHECKING:  # the server (websockets, the CDR encoders) loads only with --live
    from ocu.console.model import ConsoleModel
    from ocu.live.control import Core
    from ocu.live.goals import GoalCore
    from ocu.live.server import LiveServer

DEFAULT_HOST: Final = "127.0.0.1"
TOKEN_ENV: Final = "OCU_LIVE_TOKEN"
MIN_TOKEN_CHARS: Final = 8

L = TypeVar("L", bound=Link)


class LiveError(Exception):
    """The live server cannot start (address in use, exposed without a token)."""


def parse_live_address(text: str) -> tuple[str, int]:
    """`[HOST:]PORT` (an IPv6 host in brackets) into (host, port); loopback when no host."""
    host, sep, port_text = text.rpartition(":")
    if not sep:
        host = DEFAULT_HOST
    host = host.strip("[]") if host.startswith("[") else host
    try:
        port = int(port_text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"bad port in {text!r}: use [HOST:]PORT") from None
    if not 0 <= port <= 65535 or (sep and not host):
        raise argparse.ArgumentTypeError(f"bad address {text!r}: use [HOST:]PORT")
    return host, port


def is_loopback(host: str) -> bool:
    """Whether every address the host name stands for is a loopback one."""
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        pass
    try:
        infos = socket.getaddrinfo(host, None)
    except OSError:
        return False
    return bool(infos) and all(
        ipaddress.ip_address(str(info[4][0]).split("%")[0]).is_loopback for info in infos
    )


def check_exposure(host: str, token: str | None) -> None:
    """LiveError unless the address is loopback or a long enough token guards it."""
    if token is not None and len(token) < MIN_TOKEN_CHARS:
        raise LiveError(f"--live-token: use at least {MIN_TOKEN_CHARS} characters")
    if token is None and not is_loopback(host):
        raise LiveError(
            f"--live {host or '*'}: refusing to serve a non-loopback address without a token "
            f"(--live-token or ${TOKEN_ENV}): whoever reaches it would see the robot's "
            "cameras and position"
        )


def add_live_options(parser: argparse.ArgumentParser) -> None:
    """--live and --live-token on a command line."""
    parser.add_argument(
        "--live",
        metavar="[HOST:]PORT",
        type=parse_live_address,
        help="serve the session over the Foxglove WebSocket protocol (Foxglove, Lichtblick) on "
        f"HOST:PORT, {DEFAULT_HOST} when no HOST (docs/live.md)",
    )
    parser.add_argument(
        "--live-control",
        action="store_true",
        help="let one live client drive with /cmd_vel (Foxglove's Teleop panel) and move the "
        "arm (/joint_goals, /arm/twist_cmd, /arm/named_pose), as the input mux's `live` "
        "source: any operator input, Space, LINK LOST or focus loss stops it (docs/live.md)",
    )
    parser.add_argument(
        "--live-token",
        metavar="TOKEN",
        default=os.environ.get(TOKEN_ENV) or None,
        help=f"clients must give it (ws://HOST:PORT?token=TOKEN); needed for a non-loopback "
        f"--live; default ${TOKEN_ENV}",
    )


def start_live(
    profile: RobotProfile,
    address: tuple[str, int] | None,
    token: str | None,
    control: bool = False,
) -> LiveServer | None:
    """The started server (stopped at exit), or None without --live; LiveError if refused."""
    if address is None:
        if control:
            raise LiveError("--live-control needs --live")
        return None
    from ocu.live.server import LiveServer

    host, port = address
    check_exposure(host, token)
    server = LiveServer(profile, host, port, token=token, control=control)
    server.start()
    atexit.register(server.stop)
    return server


def serving(live: LiveServer | None, make_link: Callable[[], L]) -> Callable[[], L]:
    """`make_link` whose every link is also served live (unchanged without a server)."""
    if live is None:
        return make_link

    def make_served_link() -> L:
        link = make_link()
        live.attach(link)
        return link

    return make_served_link


def serve_console(
    live: LiveServer | None,
    core: Core,
    goals: Callable[[ConsoleModel], GoalCore] | None = None,
) -> None:
    """Serve the control core's model: a chassis's odometry and map, the zones, path and arm
    goal, and with --live-control a client's /cmd_vel and (`goals` makes the goal core) the
    arm's topics into its mux (docs/live.md); nothing without a server."""
    if live is None:
        return
    if core.model.profile.drive_channels is not None:
        live.serve_navigation(core.model.nav)
    live.serve_scene(core.model)
    made = goals(core.model) if goals is not None and live.allow_control else None
    live.serve_control(core, made)


def serve(live: LiveServer | None, link: L) -> L:
    """The link, also served live when there is a server."""
    if live is not None:
        live.attach(link)
    return link
