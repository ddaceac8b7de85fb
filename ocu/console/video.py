"""The video the robot is asked for, a part of the console model: the selected camera (the
vendor protocol streams one at a time), the RCP's video bit-rate field, and per camera what an
extended robot streams. They go out with every command (`ConsoleModel.command()`)."""

from __future__ import annotations

import math

from ocu.console.part import ModelPart
from ocu.records import CameraRequest, CommandError


class VideoRequest(ModelPart):
    """The camera, the bit-rate and the stream requests (the video views set them)."""

    @property
    def camera(self) -> int | None:
        """The camera asked for (None: none selected yet)."""
        return self._camera

    @property
    def video_bitrate(self) -> float:
        """The RCP's video bit-rate field."""
        return self._bitrate

    @property
    def stream_request(self) -> tuple[CameraRequest, ...]:
        """What an extended robot is asked to stream, per camera."""
        return self._streams

    def select_camera(self, camera: int) -> None:
        """Ask for a camera's stream (the vendor protocol sends one at a time)."""
        if not 0 <= camera < len(self.profile.link.camera_names):
            raise CommandError(
                f"camera {camera} outside 0-{len(self.profile.link.camera_names) - 1}"
            )
        if camera == self._camera:
            return
        self._camera = camera
        self.events.camera_changed.emit(camera)
        self._publish()

    def set_video_bitrate(self, bitrate: float) -> None:
        """The RCP's video bit-rate field (bits per second, >= 0)."""
        if not (math.isfinite(bitrate) and bitrate >= 0.0):
            raise CommandError(f"video bit-rate must be finite and >= 0, got {bitrate!r}")
        if bitrate == self._bitrate:
            return
        self._bitrate = float(bitrate)
        self.events.bitrate_changed.emit(self._bitrate)
        self._publish()

    def set_stream_request(self, request: CameraRequest) -> None:
        """What an extended robot should stream for one camera (size, rate)."""
        streams = list(self._streams)
        if not 0 <= request.camera < len(streams):
            raise CommandError(f"no stream request for camera {request.camera}")
        if streams[request.camera] == request:
            return
        streams[request.camera] = request
        self._streams = tuple(streams)
        self.events.stream_request_changed.emit(self._streams)
