"""The one exception type of the record package."""


class RecordingError(Exception):
    """A recording cannot be written or read (bad path, disk full, not an MCAP file)."""
