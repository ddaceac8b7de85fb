"""Recording and replay: MCAP files of link sessions (docs/recordings.md).

The recorder, reader, player and inspect modules import no Qt; replay (ReplaySource,
ReplayControls) and qt (RecordButton) are the console's Qt side.
"""

from ocu.record.errors import RecordingError
from ocu.record.reader import Recording
from ocu.record.recorder import Recorder, RecorderStats, TeeListener

__all__ = ["Recorder", "RecorderStats", "Recording", "RecordingError", "TeeListener"]
