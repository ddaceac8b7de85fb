"""What live clients send that commands the robot: client publish (`--live-control`) on the
server's loop thread in the console (docs/live.md); the relay process forwards it.

A client advertises the topics it will publish on; each must be one of ocu.live.messages's,
in one of its types, in json or cdr, and one this robot takes (a chassis for /cmd_vel, an arm
for the arm's topics). Its messages are decoded strictly and handed to LiveControl, which
decides whether this client may command now. Warnings go back as status messages, once per
reason (not once per message at 20 Hz); a message that cannot be decoded counts as refused.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from ocu.live import wire
from ocu.live.control import LiveControl
from ocu.live.messages import CMD_VEL, ENCODINGS, INPUTS, InputError, decode, schemas_of

PUBLISH_OFF = "client publish is off (ocu --live-control)"
STARTING = "not taken: the console is starting"


@dataclass
class RemoteClient:
    """The console's record of one client of the relay: what it advertised, its refusals."""

    id: int
    address: str
    published: dict[int, wire.ClientChannel] = field(default_factory=dict)
    refused: int = 0
    last_warning: str = ""


Client = RemoteClient


class ClientInputs:
    """The server's side of client publish; `teleop` is set once a console is served."""

    def __init__(self, allow: bool, send: Callable[[Client, str], None]) -> None:
        self.allow = allow
        self.send = send
        self.teleop: LiveControl | None = None
        # Told of each message the live source took (topic, decoded): the server's echo.
        self.taken: Callable[[str, Any], None] | None = None

    def warn(self, client: Client, text: str) -> None:
        """A warning status, once per reason in a row."""
        if text != client.last_warning:
            client.last_warning = text
            self.send(client, wire.status(wire.StatusLevel.WARNING, text))

    def on_message(
        self,
        client: Client,
        message: wire.ClientAdvertise | wire.ClientUnadvertise | wire.ClientPublish,
    ) -> None:
        """One client-publish message from a client."""
        if not self.allow:
            client.refused += 1
            self.send(client, wire.status(wire.StatusLevel.ERROR, PUBLISH_OFF))
            return
        if isinstance(message, wire.ClientAdvertise):
            for channel in message.channels:
                self._advertise(client, channel)
        elif isinstance(message, wire.ClientUnadvertise):
            for channel_id in message.channel_ids:
                gone = client.published.pop(channel_id, None)
                if gone is not None and self.teleop is not None:
                    self.teleop.release(client.address, f"{gone.topic} unadvertised")
        else:
            self._publish(client, message)

    def _advertise(self, client: Client, channel: wire.ClientChannel) -> None:
        schemas = schemas_of(channel.topic)
        taken = self.teleop.topics() if self.teleop is not None else tuple(INPUTS)
        if channel.schema_name not in schemas or channel.encoding not in ENCODINGS:
            known = ", ".join(f"{topic} ({schemas_of(topic)[0]})" for topic in taken)
            self.warn(
                client,
                f"{channel.topic} ({channel.schema_name}, {channel.encoding}) is not taken: "
                f"only {known or 'nothing'}, in json or cdr",
            )
            return
        if channel.topic not in taken:
            self.warn(client, f"{channel.topic} is not taken: this robot has none to command")
            return
        client.published[channel.id] = channel

    def _publish(self, client: Client, message: wire.ClientPublish) -> None:
        published = client.published.get(message.channel_id)
        if published is None:
            client.refused += 1
            self.warn(client, f"a message on channel {message.channel_id}, not advertised")
            return
        topic = published.topic
        try:
            decoded = decode(topic, published.encoding, message.payload)
        except InputError as err:
            client.refused += 1
            self.warn(client, f"{topic}: {err}")
            return
        teleop = self.teleop
        if teleop is None:  # a client that came while the console starts: not its fault
            self.warn(client, f"{topic} {STARTING}")
            return
        if topic == CMD_VEL:
            refusal = teleop.twist(client.address, *decoded)
        else:
            refusal = teleop.command(client.address, topic, decoded)
        if refusal is not None:
            self.warn(client, f"{topic} not taken: {refusal}")
        else:
            client.last_warning = ""
            if self.taken is not None:
                self.taken(topic, decoded)

    def left(self, client: Client) -> None:
        """The client has gone: what it drove stops at once."""
        if self.teleop is not None:
            self.teleop.release(client.address, "left")
