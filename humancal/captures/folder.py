"""A self-describing capture folder: the detections and ``capture.yaml`` (what the inbox sensor reads)."""

from __future__ import annotations

from pathlib import Path

from humancal.captures.config import CaptureConfig
from humancal.formats import FormatError

__all__ = ["CAPTURE_FILE", "read_capture_folder"]

CAPTURE_FILE = "capture.yaml"
"""The file that describes a capture folder (written last: its presence says the folder is complete)."""


def read_capture_folder(folder: Path) -> tuple[CaptureConfig, str]:
    """The config and sequence name of a self-describing capture folder.

    The folder holds the detections (one sub-folder of OpenPose JSON per view, or one COCO-style JSON file per
    view) and ``capture.yaml``: the options of :class:`CaptureConfig` (``views`` optional: by default the
    sub-folders, for ``format: openpose``, or the ``*.json`` files, for ``format: coco``, in sorted order; paths
    relative to the folder) and an optional ``sequence`` name (default ``"capture"``).

    Raises:
        FileNotFoundError: no ``capture.yaml``.
        ValueError: ``capture.yaml`` is not a YAML mapping of valid options (the message names the file and the
            option).
    """
    import yaml

    path = Path(folder) / CAPTURE_FILE
    try:
        options = yaml.safe_load(path.read_text())
    except yaml.YAMLError as err:
        raise FormatError(path, None, "valid YAML", str(err).replace("\n", " ")) from None
    if not isinstance(options, dict):
        raise FormatError(path, None, "a mapping of options (format, image_size, skeleton, cameras, fps)",
                          type(options).__name__)
    options = dict(options)
    sequence = str(options.pop("sequence", "capture"))
    if "views" not in options:
        fmt = options.get("format", "openpose")
        found = sorted(p for p in Path(folder).iterdir() if not p.name.startswith("."))
        found = [p for p in found if p.is_dir()] if fmt == "openpose" else [p for p in found if p.suffix == ".json"]
        options["views"] = [p.name for p in found]
    try:
        return CaptureConfig.from_options(options, Path(folder)), sequence
    except ValueError as err:
        raise ValueError(f"{path}: {err}") from None
