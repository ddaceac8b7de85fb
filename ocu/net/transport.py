"""Datagram transports under the link and the simulator: UDP, or an in-process virtual wire.

A transport moves datagrams and nothing else: no decoding, no timing. Both ends of the
protocol (ocu.link, ocu.sim) run over either one. `VirtualWire` is python-can's virtual bus
for us: two connected endpoints in one process (a Unix datagram socket pair), no network and
no port, so tests and benchmarks can run many robots at once and still go through the whole
datagram path.
"""

from __future__ import annotations

import ipaddress
import socket
from abc import ABC, abstractmethod

Address = tuple[str, int]

# The pseudo-addresses of the two ends of a virtual wire.
VIRTUAL_OCU: Address = ("virtual-ocu", 1)
VIRTUAL_ROBOT: Address = ("virtual-robot", 1)
# Room for a burst of video frames; the kernel caps this at net.core.rmem_max.
RECEIVE_BUFFER_BYTES = 4 * 1024 * 1024
# IPv4 and UDP headers: a datagram's payload is the path MTU less these.
IP_UDP_HEADER_BYTES = 28
# Linux's IP_MTU socket option (not in Python's socket module): a connected socket's path MTU.
_IP_MTU = 14
# The largest payload asked of an in-process wire (as large as a UDP datagram may be).
VIRTUAL_PAYLOAD_BYTES = 65_507


class TransportError(OSError):
    """A transport cannot be set up (unresolvable host, address in use)."""


def is_loopback(host: str) -> bool:
    """Whether a host string names a loopback address."""
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host == "localhost"


def resolve(address: Address) -> Address:
    """A host name to its IPv4 address (virtual addresses pass unchanged)."""
    if address in (VIRTUAL_OCU, VIRTUAL_ROBOT):
        return address
    try:
        return socket.gethostbyname(address[0]), address[1]
    except OSError as err:
        raise TransportError(str(err)) from err


class Transport(ABC):
    """A non-blocking datagram endpoint with a socket a selector can watch."""

    socket: socket.socket
    address: Address

    @abstractmethod
    def receive(self, buffer: bytearray) -> tuple[int, Address] | None:
        """One datagram into `buffer`: its size and sender, None when none is waiting.

        OSError for a transient receive error (an ICMP port-unreachable on UDP).
        """

    @abstractmethod
    def send(self, data: bytes, to: Address) -> None:
        """Put one datagram on the wire; OSError if it cannot."""

    def close(self) -> None:
        """Release the socket; safe to call twice."""
        self.socket.close()

    def path_payload_bytes(self, to: Address) -> int | None:
        """The largest datagram payload that reaches `to` unfragmented; None if unknown."""
        return None


class UdpTransport(Transport):
    """A UDP socket bound to `bind` (port 0: any free port)."""

    def __init__(self, bind: Address, *, receive_buffer_bytes: int = RECEIVE_BUFFER_BYTES) -> None:
        self.socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, receive_buffer_bytes)
            self.socket.bind(bind)
        except OSError as err:
            self.socket.close()
            raise TransportError(f"cannot bind {bind[0]}:{bind[1]}: {err}") from err
        self.socket.setblocking(False)
        host, port = self.socket.getsockname()[:2]
        self.address = (str(host), int(port))

    def receive(self, buffer: bytearray) -> tuple[int, Address] | None:
        try:
            size, source = self.socket.recvfrom_into(buffer)
        except (BlockingIOError, InterruptedError):
            return None
        return size, (str(source[0]), int(source[1]))

    def send(self, data: bytes, to: Address) -> None:
        self.socket.sendto(data, to)

    def path_payload_bytes(self, to: Address) -> int | None:
        """From the route's MTU (Linux IP_MTU on a connected probe socket): 65507 on the
        loopback, 1472 on a 1500-byte Ethernet or radio link."""
        try:
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
                probe.connect(to)
                mtu = probe.getsockopt(socket.IPPROTO_IP, _IP_MTU)
        except OSError:
            return None
        return max(0, min(mtu, 65_535) - IP_UDP_HEADER_BYTES) or None


class VirtualEndpoint(Transport):
    """One end of a VirtualWire: whatever it sends arrives at the other end, from it."""

    def __init__(self, sock: socket.socket, address: Address, peer: Address) -> None:
        self.socket = sock
        self.socket.setblocking(False)
        self.address = address
        self.peer = peer

    def receive(self, buffer: bytearray) -> tuple[int, Address] | None:
        try:
            size = self.socket.recv_into(buffer)
        except (BlockingIOError, InterruptedError):
            return None
        return size, self.peer

    def send(self, data: bytes, to: Address) -> None:
        if to != self.peer:
            raise OSError(f"{self.address[0]} is wired to {self.peer[0]}, not {to[0]}")
        self.socket.send(data)

    def path_payload_bytes(self, to: Address) -> int | None:
        """An in-process wire carries any UDP-sized datagram whole."""
        return VIRTUAL_PAYLOAD_BYTES


class VirtualWire:
    """Two connected in-process endpoints: `ocu` for the link, `robot` for the simulator."""

    def __init__(self) -> None:
        ocu_socket, robot_socket = socket.socketpair(socket.AF_UNIX, socket.SOCK_DGRAM)
        for sock in (ocu_socket, robot_socket):
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER_BYTES)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, RECEIVE_BUFFER_BYTES)
        self.ocu = VirtualEndpoint(ocu_socket, VIRTUAL_OCU, VIRTUAL_ROBOT)
        self.robot = VirtualEndpoint(robot_socket, VIRTUAL_ROBOT, VIRTUAL_OCU)

    def close(self) -> None:
        """Close both ends."""
        self.ocu.close()
        self.robot.close()
