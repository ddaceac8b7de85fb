"""The one exception type of the protocol package."""


class ProtocolError(ValueError):
    """A datagram or packet value that does not follow the wire format.

    Raised for a wrong length, an unknown frame type, a motor count over ten, a video payload
    that is not a JPEG, or a field value out of its wire range. The link counts and drops such
    datagrams; it never lets this escape its loop.
    """
