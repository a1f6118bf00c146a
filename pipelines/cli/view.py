"""``humancal view``: the stored result of one partition as a Rerun recording (``humancal.viewing``).

Where the capture has footage (``humancal add --videos``, or ``--videos`` here) the views' images are in the
recording and under the overlays (``humancal export overlays``); ``humancal export footage`` renders plain footage of
a synthetic scene's people, so that both can be seen without real videos.

With ``--save FILE.rrd`` the recording is written (open it with ``rerun FILE.rrd``, or drop it on
https://rerun.io/viewer); without, it is shown: in Rerun's native viewer when there is a display, else in its web
viewer served on 127.0.0.1 until Ctrl-C.
"""

from __future__ import annotations

import os
import time

from pipelines.cli.export_io import check_out, stored_table

CAMERA_KINDS = {"final": "final_cameras", "calibrated": "extrinsics", "refined": "refined_cameras",
                "reference": "gt_cameras"}
"""Camera kind shown -> the stored table it comes from."""


def add_parser(sub) -> None:
    p = sub.add_parser("view", help="look at a partition's cameras, people and meshes in 3D (Rerun)")
    p.add_argument("--partition", required=True, help="e.g. synthetic__demo")
    p.add_argument("--save", default=None, metavar="FILE.rrd", help="write the recording instead of showing it")
    p.add_argument("--full-mesh", action="store_true", help="anny's full meshes (default: decimated, lighter)")
    p.add_argument("--no-mesh", action="store_true", help="no body meshes (the skeletons only; fastest)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --save file")
    p.add_argument("--port", type=int, default=9090, help="web viewer port when there is no display")
    p.add_argument("--videos", nargs="+", metavar="PATH", default=None,
                   help="show this footage in the views: one video file or image folder per view, or one folder "
                        "holding <view>.mp4 per view (default: the footage given to `humancal add --videos`)")
    p.add_argument("--image-every", type=int, default=1, metavar="N",
                   help="log every N-th frame of the footage (a lighter file; default every frame)")
    p.set_defaults(func=cmd_view)


def _optional(asset: str, partition: str):
    """The stored table, or None when it is not stored."""
    try:
        return stored_table(asset, partition)
    except SystemExit:
        return None


def _footage(partition: str, view_names: list[str], videos: list[str] | None):
    """Per view its footage (``--videos``, else the capture's own), or None when there is none."""
    from humancal.datasets.inputs import capture_footage
    from humancal.viewing.footage import footage_for_views
    from pipelines.definitions import defs

    if videos:
        return footage_for_views(videos, view_names, "--videos")
    return capture_footage(defs.resources["datasets"].spec(partition), view_names)


def capture_view(partition: str, *, meshes: bool = True, videos: list[str] | None = None):
    """The :class:`humancal.viewing.CaptureView` of a partition's stored tables (and its footage: ``videos``, else
    the capture's own)."""
    from humancal.camera import cameras_from_table
    from humancal.fitting import FittedMotions
    from humancal.viewing import CaptureView
    from humancal.viewing.reprojection import fitted_keypoints
    from pipelines.cli.motions import _sequence_fps

    views = stored_table("views", partition)
    cameras = {}
    for kind, asset in CAMERA_KINDS.items():
        table = _optional(asset, partition)
        if table is not None and len(table):
            cameras[kind] = cameras_from_table(table)
    if "final" not in cameras:
        raise SystemExit(f"humancal: {partition} has no cameras stored yet; run `humancal update --partition {partition}`")
    fps = _sequence_fps(partition)[0]
    fitted = _optional("fitted_motions", partition)
    keypoints, vertices, faces = {}, {}, None
    if fitted is not None and len(fitted):
        motions = FittedMotions.from_table(fitted, fps)
        keypoints = fitted_keypoints(motions)
        if meshes:
            vertices, faces = _meshes(motions)
    names = views["name"].tolist()
    return CaptureView(partition, names, cameras, fps, _optional("skeletons3d", partition),
                       _optional("raw_detections", partition), _optional("associations", partition), keypoints,
                       vertices, faces, _footage(partition, names, videos))


def _meshes(motions):
    """person id -> ((T,) frames, (T, V, 3) anny vertices), and the faces (:func:`humancal.viewing.mesh.fitted_meshes`)."""
    from humancal.body import BodyModel
    from humancal.viewing.mesh import fitted_meshes
    from pipelines.quiet_warp import init_warp_quietly

    init_warp_quietly()
    return fitted_meshes(BodyModel(), motions)


def export_overlays(args) -> int:
    """``humancal export overlays``: one MP4 per view and a contact sheet (``humancal.viewing.overlays``)."""
    import numpy as np

    from humancal.viewing.overlays import write_overlays
    from pipelines.cli.motions import _frame_slice

    if args.format != "mp4":
        raise SystemExit("humancal: overlays export supports --format mp4")
    out = check_out(args.out, args.overwrite)
    view = capture_view(args.partition, meshes=False, videos=args.videos)
    frames = None
    selection = _frame_slice(args.frames)
    if selection is not None and view.detections is not None:
        numbers = np.asarray(sorted(view.detections["frame"].unique()))
        start = numbers[0] if selection.start is None else selection.start
        stop = numbers[-1] + 1 if selection.stop is None else selection.stop
        frames = numbers[(numbers >= start) & (numbers < stop) & ((numbers - start) % (selection.step or 1) == 0)]
        if len(frames) == 0:
            raise SystemExit(f"humancal: --frames {args.frames} selects none of {args.partition}'s frames "
                             f"({numbers[0]}-{numbers[-1]})")
    start = time.perf_counter()
    result = write_overlays(view, out, frames=frames, show_detections=not args.no_detections,
                            progress=lambda line: print(line, flush=True))
    drawn_on = sum(f is not None for f in view.footage or ())
    print(f"wrote {len(result.videos)} videos of {len(result.frames)} frames and {result.contact_sheet} "
          f"({'on the footage of ' + str(drawn_on) + ' views' if drawn_on else 'no footage'}, "
          f"{time.perf_counter() - start:.1f} s)")
    return 0


def export_footage(args) -> int:
    """``humancal export footage``: a synthetic scene's true bodies as silhouettes, filmed by its true cameras, one MP4
    per view (``humancal.viewing.footage.write_footage``): footage to try the overlays and the viewer on."""
    from humancal.camera import cameras_from_table
    from humancal.fitting import FittedMotions
    from humancal.viewing.footage import write_footage
    from pipelines.cli.motions import _sequence_fps

    if args.format != "mp4":
        raise SystemExit("humancal: footage export supports --format mp4")
    out = check_out(args.out, args.overwrite)
    motions_table = _optional("gt_motions", args.partition)
    if motions_table is None or not len(motions_table):
        raise SystemExit(f"humancal: {args.partition} has no true body motions (gt_motions) to film: footage is "
                         "rendered for synthetic scenes only; a capture brings its own (humancal add --videos)")
    start = time.perf_counter()
    views = stored_table("views", args.partition)
    cameras = cameras_from_table(stored_table("gt_cameras", args.partition))
    fps = _sequence_fps(args.partition)[0]
    motions = FittedMotions.from_table(motions_table, fps)
    frames = range(int(motions.frames[0]), int(motions.frames[-1]) + 1)
    if motions.frames[0] != 0:
        raise SystemExit(f"humancal: {args.partition}'s motions start at frame {motions.frames[0]}, not 0")
    meshes, faces = _meshes(motions)
    paths = write_footage(views["name"].tolist(), cameras, meshes, faces, list(frames), fps, out,
                          progress=lambda line: print(line, flush=True))
    print(f"wrote {len(paths)} videos of {len(frames)} frames under {out} ({time.perf_counter() - start:.1f} s); "
          f"draw on them: humancal export overlays --partition {args.partition} --format mp4 --videos {out} "
          f"--out overlays/")
    return 0


def cmd_view(args) -> int:
    import rerun as rr

    from humancal.viewing import blueprint, record_capture

    start = time.perf_counter()
    save = None if args.save is None else check_out(args.save, args.overwrite)
    if save is not None and save.suffix != ".rrd":
        raise SystemExit(f"humancal: --save {save}: a Rerun recording file ends in .rrd")
    if args.image_every < 1:
        raise SystemExit(f"humancal: --image-every expects a positive number of frames, got {args.image_every}")
    view = capture_view(args.partition, meshes=not args.no_mesh, videos=args.videos)
    recording = rr.RecordingStream("humancal", recording_id=args.partition)
    layout = blueprint(view.view_names)
    partial = None
    if save is not None:
        partial = save.with_name(save.name + ".partial")
        recording.save(str(partial), default_blueprint=layout)
    elif os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
        recording.spawn(default_blueprint=layout)
    else:
        url = recording.serve_grpc(default_blueprint=layout)
        rr.serve_web_viewer(web_port=args.port, open_browser=False, connect_to=url)
        print(f"web viewer: http://127.0.0.1:{args.port}/?url={url} (Ctrl-C stops it)", flush=True)
    try:
        summary = record_capture(view, recording, full_mesh=args.full_mesh, image_every=args.image_every,
                                 progress=lambda line: print(line, flush=True))
        recording.flush()
    except BaseException:
        if partial is not None:  # nothing half-written is left behind
            recording.disconnect()
            partial.unlink(missing_ok=True)
        raise
    if save is not None:
        recording.disconnect()
        partial.replace(save)
        size_mb = save.stat().st_size / 1e6
        print(f"wrote {save} ({size_mb:.1f} MB, {len(summary.entities)} entities, "
              f"{time.perf_counter() - start:.1f} s); open it with `rerun {save}`")
        return 0
    try:
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        return 0
