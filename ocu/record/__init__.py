"""Recording and replay: MCAP files of link sessions (docs/recordings.md).

No Qt here: the recorder (a Link subscriber), the reader, the replay link and inspect. The
console's Qt side is in ocu.qt (RecordButton, ReplayController) and ocu.widgets.replay.
"""

from ocu.record.errors import RecordingError
from ocu.record.reader import Recording
from ocu.record.recorder import Recorder, RecorderStats

__all__ = ["Recorder", "RecorderStats", "Recording", "RecordingError"]
