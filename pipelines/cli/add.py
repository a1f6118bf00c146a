"""``humancal add``: register a user's own capture (detector output per view) as a partition.

    humancal add NAME --openpose DIR [DIR ...] --image-size WxH [WxH ...] [--skeleton S]
                      [--cameras FILE [--cameras-format F] [--known-views NAME ...] [--refine-cameras]]
                      [--reference-cameras FILE [--reference-cameras-format F]] [--drop-view NAME ...]
                      [--fps FPS|NAME=FPS ...] [--unsynced | --time-offsets NAME=SECONDS ...]
                      [--videos PATH [PATH ...]] [--sequence SEQ]
    humancal add NAME --coco FILE [FILE ...] --image-size WxH [...]

Everything is checked first: every file is read once, and an error names the file and the field, or the view and
the flag to change (a wrong --image-size, a --skeleton the people's anatomy contradicts, views given twice or
sharing no frame); nothing is written then. Probably-wrong input that can still be used is printed as warnings.
On success the capture is added to the user datasets file (``<state dir>/datasets.yaml``, written atomically)
and the partition ``NAME__SEQ`` is registered; ``humancal update --partition NAME__SEQ`` calibrates it.
"""

from __future__ import annotations

import argparse
from pathlib import Path

DEFAULT_SEQUENCE = "capture"
"""The sequence half of a capture's partition key unless ``--sequence`` names another."""
FLAGS = {"image_size": "--image-size", "skeleton": "--skeleton", "cameras_format": "--cameras-format",
         "known_views": "--known-views", "reference_cameras_format": "--reference-cameras-format",
         "drop_views": "--drop-view", "fps": "--fps", "view_fps": "--fps", "unsynced": "--unsynced",
         "time_offsets": "--time-offsets", "videos": "--videos"}
"""How the messages of the capture checks name the options: by their flags (``views``: ``--openpose`` or
``--coco``, as given)."""


def add_parser(subparsers) -> None:
    """Add the ``add`` command to the CLI's subparsers."""
    from pipelines.cli.format_names import (  # light: --help stays fast
        CAMERA_FORMATS,
        COCO_SKELETONS,
        OPENPOSE_SKELETONS,
    )

    p = subparsers.add_parser(
        "add", help="register your own capture (OpenPose JSON folders or COCO keypoint files, one per view)",
        description="Check and register a capture: per view, an OpenPose --write_json folder or a COCO-style keypoint "
                    "JSON file (AlphaPose, MMPose/RTMPose). Writes the user datasets file and registers the partition "
                    "NAME__SEQUENCE.",
    )
    p.add_argument("name", help="dataset name (letters, digits, '-', '_'), the first half of the partition key")
    source = p.add_mutually_exclusive_group(required=True)
    source.add_argument("--openpose", nargs="+", metavar="DIR", type=Path, help="one OpenPose JSON folder per view, in view order")
    source.add_argument("--coco", nargs="+", metavar="FILE", type=Path, help="one COCO-style keypoint JSON file per view")
    p.add_argument("--image-size", nargs="+", required=True, metavar="WxH",
                   help="image size in pixels, e.g. 1920x1080: one for all views or one per view")
    p.add_argument("--skeleton", choices=[*OPENPOSE_SKELETONS, *COCO_SKELETONS],
                   help="the detector's keypoint format (required for 25-point OpenPose output: body25 or body25b)")
    p.add_argument("--cameras", type=Path, metavar="FILE",
                   help="known cameras, used instead of a calibration from the people: one per view in view order, "
                        "or one per view of --known-views (the other views are calibrated around them)")
    camera_read_formats = (*CAMERA_FORMATS, "qualisys")  # humancal.formats.CAMERA_READ_FORMATS (qualisys: read only)
    p.add_argument("--cameras-format", choices=camera_read_formats,
                   help="format of --cameras (default: from the file name: .toml pose2sim, .qca.txt qualisys, ...)")
    p.add_argument("--known-views", nargs="+", metavar="NAME",
                   help="the views (folder or file names) whose cameras --cameras holds, in the file's order")
    p.add_argument("--refine-cameras", action="store_true",
                   help="let the body fit refine the known cameras (default: they are held as given)")
    p.add_argument("--reference-cameras", type=Path, metavar="FILE",
                   help="the true cameras, one per view in view order: evaluation only (camera error rows of "
                        "`humancal report`), never used by the method")
    p.add_argument("--reference-cameras-format", choices=camera_read_formats,
                   help="format of --reference-cameras (default: from the file name)")
    p.add_argument("--drop-view", action="append", metavar="NAME", default=[],
                   help="leave this view (folder or file name) out of the capture (repeatable)")
    p.add_argument("--fps", nargs="+", metavar="FPS|NAME=FPS",
                   help="frames per second: one for all views (e.g. 30), and/or per view by name (e.g. cam2=60); "
                        "views of other rates are put on the first view's frames (nearest frame)")
    sync = p.add_mutually_exclusive_group()
    sync.add_argument("--unsynced", action="store_true",
                      help="the videos were started by hand (frame n of one view is not frame n of another): "
                           "estimate each view's time offset from the people's motion, report it and store it")
    sync.add_argument("--time-offsets", nargs="+", metavar="NAME=SECONDS",
                      help="known time offsets: view NAME's frame n was taken at n / fps + SECONDS on the first "
                           "view's clock (views not named: 0)")
    p.add_argument("--principal-point", nargs="+", metavar="CX,CY",
                   help="known principal point in pixels, e.g. 963.5,541.2: one for all views or one per view "
                        "(default: the image centre, which the calibration then assumes)")
    p.add_argument("--videos", nargs="+", metavar="PATH", type=Path,
                   help="the footage, one video file or image folder per view in view order (frame n of a view is "
                        "the video's n-th frame): drawn under `humancal export overlays` and in `humancal view`; "
                        "never used by the calibration or the fit")
    p.add_argument("--sequence", default=DEFAULT_SEQUENCE, help=f"the second half of the partition key (default {DEFAULT_SEQUENCE})")
    p.set_defaults(func=cmd_add)


def cmd_add(args: argparse.Namespace) -> int:
    """Validate the capture, write it into the user datasets file, register its partition, print a summary."""
    import dataclasses

    from humancal.captures import CaptureConfig, load_capture, parse_image_size, parse_principal_point
    from humancal.captures.options import parse_named_numbers
    from humancal.datasets.sequences import (
        DatasetsConfigError,
        add_user_sequence,
        load_datasets_config,
        partition_key,
        user_config_path,
    )

    views = [p.expanduser().resolve() for p in (args.openpose or args.coco)]
    sizes = [parse_image_size(s, "--image-size") for s in args.image_size]
    if len(sizes) == 1:
        sizes = sizes * len(views)
    elif len(sizes) != len(views):
        raise ValueError(f"--image-size: expected one size or one per view ({len(views)}), got {len(sizes)}")
    points = None
    if args.principal_point:
        points = [parse_principal_point(s, "--principal-point") for s in args.principal_point]
        if len(points) == 1:
            points = points * len(views)
        elif len(points) != len(views):
            raise ValueError(f"--principal-point: expected one point or one per view ({len(views)}), got {len(points)}")
    if args.videos and len(args.videos) != len(views):
        raise ValueError(f"--videos: expected one video file or image folder per view ({len(views)}), "
                         f"got {len(args.videos)}")
    for flag, value, needs in (("--cameras-format", args.cameras_format, args.cameras),
                               ("--known-views", args.known_views, args.cameras),
                               ("--refine-cameras", args.refine_cameras, args.cameras),
                               ("--reference-cameras-format", args.reference_cameras_format, args.reference_cameras)):
        if value and not needs:
            raise ValueError(f"{flag}: given without --{'reference-' if 'reference' in flag else ''}cameras")
    fps, view_fps = (parse_named_numbers(args.fps, "--fps", "FPS", positive=True, allow_default=True)
                     if args.fps else (None, ()))
    offsets = (parse_named_numbers(args.time_offsets, "--time-offsets", "SECONDS", positive=False,
                                   allow_default=False)[1] if args.time_offsets else ())
    config = CaptureConfig(
        format="openpose" if args.openpose else "coco",
        views=tuple(views),
        image_sizes_px=tuple(sizes),
        skeleton=args.skeleton,
        cameras=args.cameras.expanduser().resolve() if args.cameras else None,
        cameras_format=args.cameras_format,
        known_views=tuple(args.known_views) if args.known_views else None,
        refine_cameras=args.refine_cameras,
        reference_cameras=args.reference_cameras.expanduser().resolve() if args.reference_cameras else None,
        reference_cameras_format=args.reference_cameras_format,
        drop_views=tuple(args.drop_view),
        fps=fps,
        view_fps=view_fps,
        unsynced=args.unsynced,
        time_offsets_s=offsets,
        principal_points_px=tuple(points) if points else None,
        videos=tuple(p.expanduser().resolve() for p in args.videos) if args.videos else None,
    )
    key = partition_key(args.name, args.sequence)
    if key in load_datasets_config():  # the cheap check first; add_user_sequence checks again before writing
        raise DatasetsConfigError(f"partition {key} exists; choose another NAME or --sequence")
    flags = {**FLAGS, "views": "--openpose" if args.openpose else "--coco"}
    if config.unsynced:
        print("estimating the time offsets from the people's motion, then checking them with cameras calibrated "
              "from the people (up to a few minutes) ...", flush=True)
    capture = load_capture(config, args.sequence, option_names=flags)
    sync = capture.summary.sync
    if config.unsynced and sync is not None:
        # stored, so that `humancal update` applies these offsets (and the user can read and edit them) rather
        # than estimating them again
        config = dataclasses.replace(config, time_offsets_s=tuple(
            (name, round(offset, 6)) for name, offset in zip(capture.summary.names, sync.offset_s)))
    spec = add_user_sequence(args.name, args.sequence, "capture", config.to_options())
    register_capture_partition(spec.key)
    print(f"registered {spec.key} in {user_config_path()}:")
    print("\n".join(capture.summary.lines()))
    print(f"next: humancal update --partition {spec.key}\n"
          f"      humancal export cameras --partition {spec.key} --format pose2sim --out cameras.toml")
    return 0


def register_capture_partition(key: str) -> None:
    """Add ``key`` to the sequences partitions of the CLI's Dagster instance."""
    from pipelines.instance import persistent_instance
    from pipelines.partitions import SEQUENCES

    instance = persistent_instance()
    if key not in set(instance.get_dynamic_partitions(SEQUENCES.name)):
        instance.add_dynamic_partitions(SEQUENCES.name, [key])
