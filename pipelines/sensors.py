"""The capture inbox: drop a capture folder into ``<local dir>/inbox/`` and a sensor registers and calibrates it.

A drop is a folder ``<inbox>/<NAME>/`` holding the detections (one sub-folder of OpenPose JSON per view, or one
COCO-style keypoint JSON file per view) and, written last, ``capture.yaml`` (``humancal.captures.folder.read_capture_folder``)::

    format: openpose
    image_size: [1920, 1080]
    skeleton: body25
    cameras: {path: calib.toml, format: pose2sim}     # optional, evaluation only

On each tick the sensor looks at drops it has not seen in their present state (the cursor keeps a fingerprint of
each drop: ``capture.yaml``'s time and size, the number of files). A valid drop is written into the user datasets
file as dataset ``NAME`` (sequence ``capture`` unless ``capture.yaml`` names one), its partition is added and a
run of every per-sequence asset is requested for it. An invalid drop is logged with the reason (the file and
field) and not looked at again until it changes. The inbox folder is ``$HUMANCAL_INBOX`` or ``<local dir>/inbox``: a
folder of the machine the sensor runs on (the local dir is the state dir unless that is on a store:
:mod:`humancal.settings`).
"""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path

import dagster as dg

from pipelines.partitions import SEQUENCES

log = logging.getLogger(__name__)

INBOX_ENV = "HUMANCAL_INBOX"


def inbox_dir() -> Path:
    """``$HUMANCAL_INBOX`` or ``<local dir>/inbox``."""
    from humancal.settings import local_dir

    configured = os.environ.get(INBOX_ENV)
    return Path(configured).expanduser() if configured else local_dir() / "inbox"


def _fingerprint(drop: Path) -> str:
    from humancal.captures.folder import CAPTURE_FILE

    stat = (drop / CAPTURE_FILE).stat()
    files = sum(len(names) for _, _, names in os.walk(drop))
    return f"{stat.st_mtime_ns}:{stat.st_size}:{files}"


def register_drop(drop: Path, user_datasets: Path | None = None) -> str:
    """Check a drop and add it to the user datasets file; returns its partition key.

    Raises:
        ValueError, FileNotFoundError: the drop is invalid (the message names the file and field), or its name is
            taken; nothing is written then.
    """
    from humancal.captures import load_capture
    from humancal.captures.folder import read_capture_folder
    from humancal.datasets.sequences import add_user_sequence, load_datasets_config, partition_key

    config, sequence = read_capture_folder(drop)
    key = partition_key(drop.name, sequence)
    if key in load_datasets_config(user_path=user_datasets):
        raise ValueError(f"partition {key} exists; rename the folder or set 'sequence' in its capture.yaml")
    capture = load_capture(config, sequence)
    for warning in capture.summary.warnings:  # usable but probably wrong: the sensor's log says so
        log.warning("%s: %s", drop, warning)
    return add_user_sequence(drop.name, sequence, "capture", config.to_options(), user_path=user_datasets).key


def build_capture_inbox_sensor(
    inbox: Path | None = None, user_datasets: Path | None = None, minimum_interval_seconds: int = 30
) -> dg.SensorDefinition:
    """The inbox sensor (module docstring).

    Args:
        inbox: the watched folder (default :func:`inbox_dir`, looked up at each tick).
        user_datasets: the user datasets file (default ``<state dir>/datasets.yaml``).
        minimum_interval_seconds: seconds between ticks.
    """

    @dg.sensor(
        name="capture_inbox",
        asset_selection=dg.AssetSelection.groups("sequence"),
        minimum_interval_seconds=minimum_interval_seconds,
        default_status=dg.DefaultSensorStatus.RUNNING,
        description="Registers capture folders dropped into the inbox (<local dir>/inbox) and calibrates them.",
    )
    def capture_inbox(context: dg.SensorEvaluationContext) -> dg.SensorResult:
        from humancal.captures.folder import CAPTURE_FILE

        folder = inbox or inbox_dir()
        seen = json.loads(context.cursor) if context.cursor else {}
        drops = sorted(p for p in folder.iterdir() if p.is_dir()) if folder.is_dir() else []
        keys, runs = [], []
        for drop in drops:
            if not (drop / CAPTURE_FILE).is_file():
                continue  # still being copied: capture.yaml comes last
            stamp = _fingerprint(drop)
            if seen.get(drop.name) == stamp:
                continue
            seen[drop.name] = stamp
            try:
                key = register_drop(drop, user_datasets)
            except (ValueError, OSError) as err:
                context.log.warning(f"inbox: skipped {drop}: {err} (looked at again when the folder changes)")
                continue
            context.log.info(f"inbox: registered {drop} as partition {key}")
            keys.append(key)
            runs.append(dg.RunRequest(run_key=f"{key}:{stamp}", partition_key=key))
        return dg.SensorResult(
            run_requests=runs,
            dynamic_partitions_requests=[SEQUENCES.build_add_request(keys)] if keys else [],
            cursor=json.dumps(seen, sort_keys=True),
        )

    return capture_inbox


capture_inbox = build_capture_inbox_sensor()
