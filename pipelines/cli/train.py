"""``humancal train lifter|prior``: train a model here on the data root's mocap (``docs/lifter.md``,
``docs/motion_prior.md``)."""

from __future__ import annotations

import sys

from pipelines.cli import QUIET_RUN_CONFIG, _assets_missing_data, _instance, _print_active_lifter
from pipelines.quiet_warp import init_warp_quietly
from pipelines.run_guard import run_tags

__all__ = ["cmd_train"]


def cmd_train(args) -> int:
    """Train the lifter on the CMU mocap under the data root; from then on it replaces the shipped weights."""
    import dagster as dg

    if args.model == "prior":
        return _train_prior(args)

    from humancal.lifter import LifterConfig
    from pipelines.definitions import artifacts_root, build_definitions
    from resources.lifter_source import trained_lifter_path

    trained = trained_lifter_path(artifacts_root())
    if args.discard:
        if trained.exists():
            trained.unlink()
            print(f"deleted {trained}: the shipped lifter is in force again; `humancal update` re-lifts with it")
        else:
            print("no trained lifter stored: the shipped lifter is already in force")
        _print_active_lifter()
        return 0
    overrides = {k: v for k, v in (("seed", args.seed), ("epochs", args.epochs)) if v is not None}
    config = LifterConfig.default().replace(**overrides)
    defs = build_definitions(lifter_config=config)
    instance = _instance()
    selection = _selection_with_mocap(defs, instance, ["lifter_trained"], "the lifter",
                                      "; the shipped lifter stays in force")
    print(f"training the lifter ({config.epochs} epochs of {config.samples_per_epoch} samples, seed {config.seed}; "
          "about 15 minutes on 2 cores" + (", after retargeting the CMU mocap" if len(selection) == 2 else "") + ") ...",
          flush=True)
    init_warp_quietly()  # the retargeting and the prior build the body model: no CUDA-driver warning from warp
    result = dg.materialize(assets=list(defs.assets), resources=defs.resources,
                            selection=dg.AssetSelection.assets(*selection), instance=instance,
                            run_config=QUIET_RUN_CONFIG, tags=run_tags(), raise_on_error=False)
    if not result.success:
        print("humancal: training failed; the lifter in force is unchanged (see the log above)", file=sys.stderr)
        return 1
    _print_active_lifter()
    print("`humancal update` now re-lifts every sequence with it (`humancal train lifter --discard` goes back to "
          "the shipped weights)")
    return 0


def _train_prior(args) -> int:
    """Train one variant of the motion prior (partition of ``motion_prior_trained``) and compute its held-out
    figures (``prior_metrics``), retargeting the mocap first if it never was."""
    import dagster as dg

    from humancal.prior import PRIOR_VARIANTS, PriorConfig
    from pipelines.definitions import build_definitions

    if args.discard:
        raise SystemExit("humancal: --discard applies to the lifter only (the trained prior is an artifact of the graph)")
    variant = args.variant or "motion_prior"
    overrides = {k: v for k, v in (("seed", args.seed), ("epochs", args.epochs)) if v is not None}
    configs = {v: PriorConfig.default(v).replace(**overrides) if v == variant else PriorConfig.default(v)
               for v in PRIOR_VARIANTS}
    defs = build_definitions(prior_configs=configs)
    instance = _instance()
    selection = _selection_with_mocap(defs, instance, ["motion_prior_trained", "prior_metrics"], "the motion prior")
    config = configs[variant]
    print(f"training the motion prior '{variant}' ({config.epochs} epochs of {config.steps_per_epoch} steps, seed "
          f"{config.seed}" + (", after retargeting the CMU mocap" if len(selection) == 3 else "") + "), then its "
          "held-out figures ...", flush=True)
    init_warp_quietly()  # the retargeting and the prior build the body model: no CUDA-driver warning from warp
    result = dg.materialize(assets=list(defs.assets), resources=defs.resources, partition_key=variant,
                            selection=dg.AssetSelection.assets(*selection), instance=instance,
                            run_config=QUIET_RUN_CONFIG, tags=run_tags(), raise_on_error=False)
    if not result.success:
        print("humancal: training the motion prior failed (see the log above)", file=sys.stderr)
        return 1
    print("`humancal report --partition cmu_mocap__held_out_02_14` shows its figures")
    if variant == "motion_prior":
        print("`humancal update` now refits every sequence's bodies with it (the body fit's prior is the "
              "motion_prior_checkpoint asset: this prior)")
    return 0


def _selection_with_mocap(defs, instance, assets: list[str], what: str, consequence: str = "") -> list:
    """The asset keys that train ``what``, with ``mocap_clips`` first when it was never materialized.

    Raises:
        SystemExit: the data root lacks the mocap (the message names the folder and ``HUMANCAL_DATA_DIR``).
    """
    import dagster as dg

    mocap = dg.AssetKey("mocap_clips")
    missing = _assets_missing_data(defs)
    if mocap in missing:
        raise SystemExit(f"humancal: training {what} needs {missing[mocap]}/ under the data root (set "
                         f"HUMANCAL_DATA_DIR){consequence}")
    selection = [dg.AssetKey(name) for name in assets]
    if instance.get_latest_materialization_event(mocap) is None:
        selection.insert(0, mocap)
    return selection
