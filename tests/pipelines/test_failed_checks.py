"""Failed checks are loud: the real ``extrinsics`` asset (its calibration replaced by a fixed rig) fails its
blocking ``rig_geometry`` check on a camera below the floor; what depends on it is not computed, ``humancal demo``
and ``humancal update`` print every failed check and exit 1; warnings are printed and exit 0. Toy inputs, an
in-memory instance: no external data, no body model, no lifter.
"""

from pathlib import Path
from types import SimpleNamespace

import dagster as dg
import numpy as np
import pandas as pd
import pytest

import assets.calibration as calibration
import pipelines.cli as cli
import pipelines.definitions
from assets.checks import latest_check_outcomes
from assets.common import sequence_asset
from assets.run_records import recorded_failed_checks
from evaluation.camera_metrics import camera_metrics_table
from humancal.camera import Camera
from pipelines.partitions import SEQUENCES
from pipelines.update import update

BELOW, LOOSE, ODD = "toy__below", "toy__loose", "toy__odd"
"""A partition whose rig has a camera below the floor and one focal that is loose, one whose rig is fine but the
people gave no floor (a warning), and one whose view 2 disagrees with the people the others triangulate."""
PEOPLE = np.array([[0.5, 0.3, 0.0], [-0.4, 0.6, 0.0], [0.0, -0.7, 0.0]])


def _look_at(centre, target, f=1000.0, size=(1920, 1080)) -> Camera:
    z = np.asarray(target, float) - centre
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    K = np.array([[f, 0, size[0] / 2], [0, f, size[1] / 2], [0, 0, 1.0]])
    return Camera.from_center(K, np.stack([x, np.cross(z, x), z]), np.asarray(centre, float), *size)


def _calibration(partition: str):
    """What ``estimate_extrinsics`` returns, for a rig of four cameras around the people."""
    angles = np.linspace(0, 2 * np.pi, 4, endpoint=False)
    cameras = [_look_at(np.array([5 * np.cos(a), 5 * np.sin(a), 2.5]), [0, 0, 1.0]) for a in angles]
    if partition == BELOW:
        cameras[1] = _look_at(np.array([0.0, 5.0, -0.5]), [0, 0, -1.0])
    loose = partition == BELOW
    per_view = pd.DataFrame({"view": range(4), "focal_px": 1000.0, "focal_rel_std": [0.01, 0.08 if loose else 0.03,
                                                                                      0.01, 0.01],
                             "focal_status": ["ok", "poorly_constrained" if loose else "ok", "ok", "ok"],
                             "bundle_status": "ok",
                             "agreement": ["ok"] * 4, "agreement_reason": [""] * 4, "loo_error_sigma": 1.5,
                             "reregistered": False})
    if partition == ODD:
        per_view.loc[2, ["agreement", "agreement_reason"]] = [
            "disagrees", "only 12 % of its detections lie near a person the other views place (at least 60 %)"]
    floor = SimpleNamespace(floor_points_m=PEOPLE, up_source="floor_plane", up_std_deg=0.1, contact_groups=3,
                            standing_groups=3, floor_rms_m=0.01)
    no_floor = partition == LOOSE
    diagnostics = SimpleNamespace(floor=None if no_floor else floor, per_view=per_view, bundle_inlier_fraction=1.0,
                                  world_frame="camera_0" if no_floor else "floor",
                                  floor_problem="only 2 standing people" if no_floor else None,
                                  people_world_m=PEOPLE + [0.0, 0.0, 1.0],
                                  body_size_ratio=1.0, mismatched_detections=0, regroup="regrouped",
                                  regroup_detections=(40, 60), scale_factor=1.0, lens=None)
    return SimpleNamespace(cameras=cameras, diagnostics=diagnostics)


@pytest.fixture
def defs(tmp_path, monkeypatch):
    """Toy inputs -> the real extrinsics asset -> a toy reader, stored by a pickling IO manager."""
    monkeypatch.setattr(calibration, "_calibration_inputs", lambda detections: (None, None))
    monkeypatch.setattr(calibration, "intrinsics_from_table", lambda table: table["sequence"].iloc[0])
    monkeypatch.setattr(calibration, "estimate_extrinsics",
                        lambda dense, lifted, partition, config, **kwargs: _calibration(partition))
    monkeypatch.setattr(calibration, "plot_rigs", lambda *args, **kwargs: Path(args[3]).write_bytes(b"png") and args[3])

    def toy(name):
        @dg.asset(name=name, partitions_def=SEQUENCES, group_name="sequence")
        def _toy(context: dg.AssetExecutionContext) -> pd.DataFrame:
            return pd.DataFrame({"sequence": [context.partition_key]})

        return _toy

    @sequence_asset("metrics", code_version="1")
    def metric_tables(extrinsics: pd.DataFrame) -> pd.DataFrame:
        return extrinsics

    @dg.asset(name="known_cameras", partitions_def=SEQUENCES, group_name="sequence")
    def known_cameras() -> pd.DataFrame:
        return pd.DataFrame()

    return dg.Definitions(
        assets=[toy("detections"), toy("intrinsics"), toy("views"), known_cameras, calibration.extrinsics,
                metric_tables],
        resources={"io_manager": dg.FilesystemIOManager(base_dir=str(tmp_path / "artifacts"))},
    )


@pytest.fixture
def instance():
    inst = dg.DagsterInstance.ephemeral()
    inst.add_dynamic_partitions(SEQUENCES.name, [BELOW, LOOSE, ODD])
    return inst


def _materialized(instance, asset: str, partition: str) -> bool:
    return instance.get_latest_materialization_event(dg.AssetKey(asset)) is not None and bool(
        instance.fetch_materializations(
            dg.AssetRecordsFilter(asset_key=dg.AssetKey(asset), asset_partitions=[partition]), limit=1).records)


def test_a_failed_blocking_check_holds_back_its_downstream_in_that_partition_only(defs, instance):
    result = update(defs, instance)
    assert ("extrinsics", BELOW) in result.materialized  # stored, with its failed check, for a person to look at
    assert ("metric_tables", LOOSE) in result.materialized
    assert ("metric_tables", BELOW) not in result.materialized and not _materialized(instance, "metric_tables", BELOW)
    assert result.failed == () and result.blocking_failed
    failed = {(o.partition, o.check): o for o in result.checks}
    rig = failed[(BELOW, "rig_geometry")]
    assert rig.blocks and "view 1: camera centre -0.50 m is not above the floor" in rig.description
    loose = failed[(BELOW, "focal_constrained")]  # a focal not determined to 5 % blocks too, and says why
    assert loose.blocks and "view 1: focal 1000 px +- 8 %" in loose.description
    warning = failed[(LOOSE, "floor_found")]
    assert not warning.blocks and warning.severity == "WARN" and "only 2 standing people" in warning.description
    odd = failed[(ODD, "views_agree")]  # the wrong view is named, with the figure and the way out
    assert odd.blocks and "view 2 disagrees with the other views: only 12 % of its detections" in \
        odd.description and "--drop-view" in odd.description
    assert ("metric_tables", ODD) not in result.materialized
    assert ("metric_tables", BELOW, "held back: extrinsics[toy__below] failed its blocking check rig_geometry; "
                                    "extrinsics[toy__below] failed its blocking check focal_constrained") in result.waiting
    assert result.earlier_checks == ()

    again = update(defs, instance)  # nothing new runs, and the failure still holds metric_tables back
    assert again.materialized == () and again.blocking_failed
    assert sorted((o.partition, o.check) for o in again.earlier_checks) == [
        (BELOW, "focal_constrained"), (BELOW, "rig_geometry"), (ODD, "views_agree")]
    assert ("metric_tables", BELOW) in {(a, p) for a, p, _ in again.waiting}


def test_the_recorded_outcomes_are_those_of_the_latest_materialization(defs, instance):
    update(defs, instance)
    below = {o.check: o for o in latest_check_outcomes(instance, dg.AssetKey("extrinsics"), BELOW)}
    loose = {o.check: o for o in latest_check_outcomes(instance, dg.AssetKey("extrinsics"), LOOSE)}
    assert set(below) == set(loose) == {"cameras_valid", "focal_plausible", "rig_geometry", "focal_constrained",
                                        "floor_found", "people_plausible", "views_agree"}
    assert not below["rig_geometry"].passed and loose["rig_geometry"].passed
    assert below["rig_geometry"].blocking and below["focal_constrained"].blocking and not loose["floor_found"].blocking
    assert latest_check_outcomes(instance, dg.AssetKey("metric_tables"), BELOW) is None


@pytest.fixture
def cli_on(defs, instance, monkeypatch, tmp_path):
    """The CLI on the toy graph: its instance, no datasets to register, a stand-in for the stored metric table."""
    monkeypatch.setenv("HUMANCAL_STATE_DIR", str(tmp_path / "state"))
    monkeypatch.setattr(pipelines.definitions, "defs", defs)
    monkeypatch.setattr(cli, "_instance", lambda: instance)
    monkeypatch.setattr(cli, "register_partitions", lambda instance, defs: [BELOW, LOOSE, ODD])
    monkeypatch.setattr(cli, "_check_partitions", lambda requested, defs: None)
    monkeypatch.setattr(cli, "_report_missing_data", lambda defs, emit=print: {})
    monkeypatch.setattr(cli, "_print_active_lifter", lambda emit=print: None)
    table = pd.DataFrame({"dataset": ["toy"], "sequence": ["loose"], "method": ["int_ext"],
                          "metric": ["focal_error_pct"], "value": [1.5], "unit": ["%"]})
    monkeypatch.setattr(cli, "_stored_metrics", lambda partitions, headline_only: table)

    def run(*argv, demo_partition=None):
        if demo_partition:
            monkeypatch.setattr(cli, "DEMO_PARTITION", demo_partition)
        return cli.main(list(argv))

    return run


def test_demo_exits_1_with_the_failed_blocking_check_and_its_message(cli_on, instance, capsys):
    assert cli_on("demo", demo_partition=BELOW) == 1
    err = capsys.readouterr().err
    assert "ERROR extrinsics[toy__below] rig_geometry: view 1: camera centre -0.50 m is not above the floor" in err
    assert "ERROR extrinsics[toy__below] focal_constrained: view 1: focal 1000 px" in err
    assert "no metric table" in err and "focal_error_pct" not in err
    assert not _materialized(instance, "metric_tables", BELOW)


def test_demo_with_warnings_only_prints_them_above_the_table_and_exits_0(cli_on, capsys):
    assert cli_on("demo", demo_partition=LOOSE) == 0
    out, err = capsys.readouterr()
    assert "WARN extrinsics[toy__loose] floor_found" in err and "ERROR" not in err
    assert "| cameras | focal length error |  1.50 | %    |" in out  # the short headline table
    assert cli_on("demo", "--all", demo_partition=LOOSE) == 0
    assert "focal_error_pct" in capsys.readouterr().out  # --all: the metric table's rows as they are


def test_a_blocking_check_fails_the_update_that_found_it_then_is_a_reminder(cli_on, capsys):
    assert cli_on("update", "-v") == 1
    out, err = capsys.readouterr()
    assert "ERROR extrinsics[toy__below] rig_geometry: view 1: camera centre" in err
    assert "left metric_tables[toy__below]: held back: extrinsics[toy__below] failed its blocking check" in out
    # a plain update: nothing changed, the same check still fails: a reminder, and exit 0 (nothing new went wrong)
    assert cli_on("update") == 0
    out, err = capsys.readouterr()
    assert "ERROR extrinsics[toy__below] rig_geometry (evaluated by an earlier run)" in err
    assert "floor_found" not in err  # a warning is printed by the run that found it
    assert "left metric_tables" not in out  # what was left waiting: with -v only
    # the partition asked for by name cannot be brought up to date: exit 1
    assert cli_on("update", "--partition", BELOW) == 1
    assert "ERROR extrinsics[toy__below] rig_geometry (evaluated by an earlier run)" in capsys.readouterr().err



def test_metric_rows_of_cameras_that_failed_a_check_name_it(defs, instance, capsys):
    """metric_tables marks its camera rows with the failed checks of the extrinsics it reads; ``report`` shows
    the column only when some row is marked."""
    update(defs, instance)  # extrinsics of both partitions, with their checks

    def flags(partition):
        return recorded_failed_checks(instance, partition)

    assert flags(BELOW) == "focal_constrained,rig_geometry" and flags(LOOSE) == "floor_found"
    assert flags("toy__never") == "unchecked"  # no recorded checks is not a pass
    rig = _calibration(BELOW).cameras
    rows = camera_metrics_table("toy", "below", rig, rig, failed_checks=flags(BELOW))
    assert set(rows["failed_checks"]) == {"focal_constrained,rig_geometry"} and len(rows) > 3
    cli._print_metrics(rows.drop(columns="view"), "md")
    assert "focal_constrained,rig_geometry" in capsys.readouterr().out
    cli._print_metrics(rows.assign(failed_checks="").drop(columns="view"), "md")
    assert "failed_checks" not in capsys.readouterr().out
