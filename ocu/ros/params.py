"""The node's parameters from its command line and its log on ROS's (rospy, no Qt).

- `is_private_arg`: rospy's rule for a `_name:=value` argument;
- `CommandLineParams`: this run's `_name:=value` arguments on the parameter server, taken
  back at exit;
- `route_logging_to_ros`: ocu's log records through rospy's logger (the console and /rosout).
"""

from __future__ import annotations

import logging
import re
from collections.abc import Mapping
from typing import Any, Protocol

log = logging.getLogger("ocu.ros")


# rospy's rule for a private parameter argument (rospy.client.load_command_line_node_params):
# one leading underscore, then a name; "__name:=" and the like are special keys.
_PRIVATE_ARG = re.compile(r"_(?!_)[\w/]+:=.*")


def is_private_arg(arg: str) -> bool:
    """Whether a command-line argument sets a private parameter (`_name:=value`)."""
    return _PRIVATE_ARG.fullmatch(arg) is not None


class ParamServer(Protocol):
    """The parts of rospy's parameter API the node uses (the rospy module itself)."""

    def resolve_name(self, name: str) -> str: ...

    def has_param(self, param_name: str) -> bool: ...

    def get_param(self, param_name: str, default: Any = ...) -> Any: ...

    def set_param(self, param_name: str, param_value: Any) -> None: ...

    def delete_param(self, param_name: str) -> None: ...


class CommandLineParams:
    """This run's `_name:=value` arguments on the parameter server, taken back at exit.

    Left there (as rospy leaves them), a value would silently hold for every later run of
    the node without the argument. `upload` remembers what each one replaced in the node's
    private namespace and `undo` puts that back, or deletes the parameter if there was none;
    nothing outside the private namespace, and no parameter the command line did not set,
    is touched.
    """

    def __init__(self, server: ParamServer) -> None:
        self.server = server
        # (resolved name, whether it existed, its value before) in upload order.
        self._replaced: list[tuple[str, bool, Any]] = []

    def upload(self, values: Mapping[str, Any]) -> None:
        """Put each value on the server as a private parameter (~name)."""
        for name, value in values.items():
            key = self.server.resolve_name("~" + name)
            existed = bool(self.server.has_param(key))
            previous = self.server.get_param(key) if existed else None
            self._replaced.append((key, existed, previous))
            self.server.set_param(key, value)

    def get(self, name: str, default: Any) -> Any:
        """A private parameter's value (a ParamGetter)."""
        return self.server.get_param("~" + name, default)

    def undo(self) -> None:
        """Restore what upload replaced; idempotent, never raises."""
        replaced, self._replaced = self._replaced, []
        for key, existed, previous in reversed(replaced):
            try:
                if existed:
                    self.server.set_param(key, previous)
                else:
                    self.server.delete_param(key)
            except KeyError:
                pass  # already deleted by someone else: nothing left behind
            except Exception as err:  # the master may be gone; the exit code must survive
                log.warning("could not take %s back from the parameter server: %s", key, err)


class _ToRosout(logging.Handler):
    """Sends ocu's log records through rospy's logger: the console and /rosout."""

    def emit(self, record: logging.LogRecord) -> None:
        logging.getLogger("rosout").handle(record)


def route_logging_to_ros() -> None:
    ocu_logger = logging.getLogger("ocu")
    ocu_logger.handlers[:] = [_ToRosout()]
    ocu_logger.setLevel(logging.INFO)
    ocu_logger.propagate = False
