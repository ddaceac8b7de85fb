"""The live server's services (the protocol's `services` capability; docs/live.md).

- `/estop` (`std_srvs/srv/Trigger`): the e-stop, as Space: everything stops at once and stays
  latched until the operator acts at the console. Offered with `--live` alone: a remote stop
  is harmless, and any watcher who sees danger may press it. There is no service that
  releases it: releasing stays the operator's, at the console.
- `/arm/move_to_named_pose` (`ocu_msgs/srv/NamedPose`: `string name` -> `bool success`,
  `string message`): a stored pose by name, exactly as `/arm/named_pose` published
  (ocu.live.control: one client at a time, the mux's locks). Only with `--live-control` on
  a robot with an arm.

A call answers in the encoding it came in (json or cdr). The e-stop's request is not read at
all: whatever its bytes, it stops.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any, Final

from mcap_ros2._dynamic import generate_dynamic

from ocu.live import wire
from ocu.live.control import Core, LiveControl
from ocu.live.messages import NAMED_POSE, InputError
from ocu.record import schemas as s

ESTOP: Final = "/estop"
MOVE_TO_NAMED_POSE: Final = "/arm/move_to_named_pose"
TRIGGER: Final = "std_srvs/srv/Trigger"
NAMED_POSE_SERVICE: Final = "ocu_msgs/srv/NamedPose"
RESPONSE_DEFINITION: Final = "bool success\nstring message\n"
NAME_DEFINITION: Final = "string name\n"
ESTOP_DONE: Final = "e-stop latched: the operator releases it at the console"

_respond = s.make_encoder(s.MessageType(f"{TRIGGER}_Response", RESPONSE_DEFINITION))
_read_name = generate_dynamic(f"{NAMED_POSE_SERVICE}_Request", NAME_DEFINITION)[
    f"{NAMED_POSE_SERVICE}_Request"
]


@dataclass(frozen=True)
class Service:
    """One advertised service."""

    id: int
    name: str
    type: str
    request: str  # its ros2msg definition

    def advertisement(self) -> dict[str, Any]:
        def part(kind: str, definition: str) -> dict[str, str]:
            return {
                "encoding": wire.MESSAGE_ENCODING,
                "schemaName": f"{self.type}_{kind}",
                "schemaEncoding": wire.SCHEMA_ENCODING,
                "schema": definition,
            }

        return {
            "id": self.id,
            "name": self.name,
            "type": self.type,
            "request": part("Request", self.request),
            "response": part("Response", RESPONSE_DEFINITION),
            # For clients that read only the protocol's first fields.
            "requestSchema": self.request,
            "responseSchema": RESPONSE_DEFINITION,
        }


class Services:
    """The services of one served console (none until `serve` is called)."""

    def __init__(self) -> None:
        self.core: Core | None = None
        self.teleop: LiveControl | None = None
        self.services: dict[int, Service] = {}

    def serve(self, core: Core, teleop: LiveControl | None) -> None:
        """Offer the e-stop on this core, and the named poses through `teleop` (if any)."""
        self.core, self.teleop = core, teleop
        services = [Service(1, ESTOP, TRIGGER, "")]
        if teleop is not None and NAMED_POSE in teleop.topics():
            services.append(Service(2, MOVE_TO_NAMED_POSE, NAMED_POSE_SERVICE, NAME_DEFINITION))
        self.services = {service.id: service for service in services}

    def advertisement(self) -> str | None:
        """The advertiseServices message (None: no service yet)."""
        if not self.services:
            return None
        listed = [service.advertisement() for service in self.services.values()]
        return json.dumps({"op": "advertiseServices", "services": listed}, separators=(",", ":"))

    def call(self, client: str, request: wire.ServiceCallRequest) -> str | bytes:
        """The answer to one call: a serviceCallResponse frame, or a serviceCallFailure."""
        service = self.services.get(request.service_id)
        if service is None:
            return wire.service_call_failure(
                request.service_id, request.call_id, f"no service {request.service_id}"
            )
        if request.encoding not in ("json", "cdr"):
            return wire.service_call_failure(
                request.service_id,
                request.call_id,
                f"encoding {request.encoding!r:.40}: json or cdr",
            )
        if service.name == ESTOP:
            success, message = self._estop(client), ESTOP_DONE
        else:
            try:
                name = _name(request.encoding, request.payload)
            except InputError as err:
                return wire.service_call_failure(request.service_id, request.call_id, str(err))
            assert self.teleop is not None
            refusal = self.teleop.command(client, NAMED_POSE, name)
            success = refusal is None
            message = f"moving the arm to {name}" if refusal is None else refusal
        answer = {"success": success, "message": message}
        payload = json.dumps(answer).encode() if request.encoding == "json" else _respond(answer)
        return wire.service_call_response(
            request.service_id, request.call_id, request.encoding, payload
        )

    def _estop(self, client: str) -> bool:
        assert self.core is not None
        with self.core.lock:
            self.core.model.emergency_stop(f"live client {client}")
        return True


def _name(encoding: str, payload: bytes) -> str:
    try:
        name = json.loads(payload)["name"] if encoding == "json" else _read_name(payload).name
    except Exception as err:  # JSON, a missing key, bytes the decoder cannot take
        raise InputError(f"not a NamedPose request: {type(err).__name__}: {err}") from err
    if not isinstance(name, str):
        raise InputError("name must be a string")
    return name
