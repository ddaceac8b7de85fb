"""Finding ROS 1: Debian installs rospy for its own python3, outside a virtual environment."""

from __future__ import annotations

import http.client
import importlib.util
import os
import shutil
import sys
import xmlrpc.client
from pathlib import Path

DEBIAN_DIST_PACKAGES = Path("/usr/lib/python3/dist-packages")
ROS_DEBIAN_PACKAGES = (
    "ros-core",
    "python3-rospy",
    "python3-geometry-msgs",
    "python3-sensor-msgs",
    "python3-diagnostic-msgs",
    "python3-std-msgs",
    "python3-nav-msgs",
    "python3-tf2-msgs",
)
ROS_PYTHON_MODULES = (
    "rospy",
    "rosgraph",
    "geometry_msgs",
    "sensor_msgs",
    "diagnostic_msgs",
    "std_msgs",
    "nav_msgs",
    "tf2_msgs",
)
DEFAULT_MASTER_URI = "http://localhost:11311"
INSTALL_HINT = "install Debian's ROS 1: sudo apt-get install " + " ".join(ROS_DEBIAN_PACKAGES)


def ensure_ros_path() -> None:
    """Make Debian's rospy importable from a virtual environment.

    The directory is appended, not prepended, so the environment's own packages (numpy,
    PyYAML) still win over Debian's copies.
    """
    if importlib.util.find_spec("rospy") is not None:
        return
    if (DEBIAN_DIST_PACKAGES / "rospy").is_dir() and str(DEBIAN_DIST_PACKAGES) not in sys.path:
        sys.path.append(str(DEBIAN_DIST_PACKAGES))


def missing_ros() -> str | None:
    """Why ROS 1 cannot be used here (None when roscore and the Python modules are present)."""
    ensure_ros_path()
    missing = [name for name in ROS_PYTHON_MODULES if importlib.util.find_spec(name) is None]
    if shutil.which("roscore") is None:
        missing.insert(0, "roscore")
    if not missing:
        return None
    return f"ROS 1 not found ({', '.join(missing)} missing); {INSTALL_HINT}"


class _TimeoutTransport(xmlrpc.client.Transport):
    def __init__(self, timeout_s: float) -> None:
        super().__init__()
        self.timeout_s = timeout_s

    def make_connection(self, host: tuple[str, dict[str, str]] | str) -> http.client.HTTPConnection:
        connection = super().make_connection(host)
        connection.timeout = self.timeout_s
        return connection


def master_uri() -> str:
    """$ROS_MASTER_URI, or ROS's default."""
    return os.environ.get("ROS_MASTER_URI") or DEFAULT_MASTER_URI


def master_online(uri: str | None = None, timeout_s: float = 1.0) -> bool:
    """Whether a ROS master answers at `uri` ($ROS_MASTER_URI if None); ROS not needed."""
    return master_pid(uri, timeout_s) is not None


def master_pid(uri: str | None = None, timeout_s: float = 1.0) -> int | None:
    """The process id of the ROS master at `uri` (a restarted master has another), None
    when none answers."""
    proxy = xmlrpc.client.ServerProxy(uri or master_uri(), transport=_TimeoutTransport(timeout_s))
    try:
        reply = proxy.getPid("/ocu_probe")
    except (OSError, xmlrpc.client.Error, ValueError):
        return None
    finally:
        proxy("close")()
    # ROS master API: [code, status message, pid], code 1 = success.
    if isinstance(reply, list) and len(reply) == 3 and reply[0] == 1:
        return int(reply[2])
    return None


def master_knows(
    node_name: str, node_uri: str, uri: str | None = None, timeout_s: float = 1.0
) -> bool | None:
    """Whether the master at `uri` has `node_name` registered at `node_uri`; None when the
    master does not answer. A restarted master has forgotten every node (rospy does not
    register again): False."""
    proxy = xmlrpc.client.ServerProxy(uri or master_uri(), transport=_TimeoutTransport(timeout_s))
    try:
        reply = proxy.lookupNode("/ocu_probe", node_name)
    except (OSError, xmlrpc.client.Error, ValueError):
        return None
    finally:
        proxy("close")()
    if not (isinstance(reply, list) and len(reply) == 3):
        return None
    # [1, status, uri] when known; [-1, "unknown node", ""] when not.
    return reply[0] == 1 and str(reply[2]).rstrip("/") == node_uri.rstrip("/")
