"""Looking at a result: a capture's cameras, people, fitted meshes and 2D evidence as a Rerun recording.

Example:
    >>> import rerun as rr  # doctest: +SKIP
    >>> from humancal.viewing import CaptureView, record_capture  # doctest: +SKIP
    >>> recording = rr.RecordingStream("humancal"); recording.save("capture.rrd")  # doctest: +SKIP
    >>> record_capture(CaptureView("mine", ["cam0"], {"final": rig}, 30.0), recording)  # doctest: +SKIP
"""

from humancal.viewing.mesh import decimation
from humancal.viewing.recording import (
    CAMERA_COLOURS,
    CaptureView,
    RecordingSummary,
    blueprint,
    person_colour,
    record_capture,
)

__all__ = ["CAMERA_COLOURS", "CaptureView", "RecordingSummary", "blueprint", "decimation", "person_colour", "record_capture"]
