"""``humancal export detections|cameras|motions|overlays|footage``: stored artifacts of a partition in other tools'
formats, under the one rule of :mod:`pipelines.cli.export_io` for where they write.
"""

from __future__ import annotations


from pipelines.cli.export_io import check_out, stored_table

__all__ = ["CAMERA_ASSETS", "check_out", "cmd_export", "stored_table"]

CAMERA_ASSETS = {"final_cameras": "final", "extrinsics": "calibrated", "refined_cameras": "refined",
                 "gt_cameras": "ground-truth"}
"""Stored camera tables ``export cameras`` knows by what they are; ``final_cameras`` (the run's last word: the
refined cameras when the refinement passed its check, else the calibrated ones) is the default."""


def cmd_export(args) -> int:
    """Hand detections, cameras or motions of a partition to other tools (OpenPose JSON; Pose2Sim, anipose,
    EasyMocap, COLMAP, Shelf or humancal camera files; BVH, glTF, npz, OBJ)."""
    try:
        return _export(args)
    except PermissionError as err:  # checked up front; a file inside the folder can still refuse
        raise SystemExit(f"humancal: cannot write {err.filename or args.out}: {err.strerror}; choose another --out "
                         "or make it writable") from None
    except OSError as err:
        if err.filename is None:
            raise
        raise SystemExit(f"humancal: cannot write {err.filename}: {err.strerror}") from None


def _export(args) -> int:
    for flag, given in (("--videos", getattr(args, "videos", None)), ("--no-detections", getattr(args, "no_detections", False))):
        if given and args.what != "overlays":
            raise SystemExit(f"humancal: {flag} is an option of `export overlays`, not of `export {args.what}`")
    if args.what in ("overlays", "footage"):
        from pipelines.cli.view import export_footage, export_overlays

        return export_overlays(args) if args.what == "overlays" else export_footage(args)
    if args.what == "motions":
        from pipelines.cli.format_names import MOTION_FORMATS
        from pipelines.cli.motions import export_stored_motions

        if args.format in MOTION_FORMATS:  # an unknown format is refused with the known ones, below
            check_out(args.out, args.overwrite)
        return export_stored_motions(args, lambda: stored_table("fitted_motions", args.partition))
    if args.what == "detections":
        from humancal.formats import write_openpose

        if args.format != "openpose":
            raise SystemExit("humancal: detections export supports --format openpose")
        check_out(args.out, args.overwrite)
        folders = write_openpose(stored_table("raw_detections", args.partition), args.out, overwrite=args.overwrite)
        print(f"wrote OpenPose JSON for {len(folders)} views under {args.out}")
        return 0
    from humancal.camera import cameras_from_table
    from humancal.formats import write_cameras

    asset = _cameras_asset(args)
    table = stored_table(asset, args.partition)
    check_out(args.out, args.overwrite)
    cameras = cameras_from_table(table)
    names = _view_names(args.partition, len(cameras)) if args.format != "shelf" else None  # shelf: numbers only
    path = write_cameras(cameras, args.out, args.format, names=names)
    what = CAMERA_ASSETS.get(asset, "stored")
    source = f"; {final_source(args.partition)}" if asset == "final_cameras" else ""
    print(f"wrote {len(cameras)} {what} cameras (asset {asset}{source}, format {args.format}) to {path}")
    return 0


def _view_names(partition: str, count: int) -> list[str] | None:
    """The partition's view names (folder names of a capture), when stored, distinct and as many as the cameras."""
    try:
        views = stored_table("views", partition).sort_values("view")
    except SystemExit:  # not stored (cameras written by hand): the default names
        return None
    names = views["name"].astype(str).tolist() if "name" in views.columns else []
    return names if len(names) == count and len(set(names)) == count else None


def final_source(partition: str) -> str:
    """Which cameras ``final_cameras`` of a partition holds, and why (from its latest materialization)."""
    import dagster as dg

    from pipelines.instance import persistent_instance

    records = persistent_instance().fetch_materializations(dg.AssetRecordsFilter(
        asset_key=dg.AssetKey("final_cameras"), asset_partitions=[partition]), limit=1).records
    meta = records[0].asset_materialization.metadata if records else {}
    source, reason = meta.get("source"), meta.get("reason")
    return f"the {source.value}: {reason.value}" if source and reason else "source not recorded"


def _cameras_asset(args) -> str:
    """The estimated cameras unless the ground truth (or another stored cameras table) is asked for by name."""
    if args.ground_truth and args.cameras_asset not in (None, "gt_cameras"):
        raise SystemExit(f"humancal: --ground-truth and --cameras-asset {args.cameras_asset} contradict each other")
    if args.ground_truth:
        return "gt_cameras"
    return args.cameras_asset or "final_cameras"
