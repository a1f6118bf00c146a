"""``humancal remove NAME [--sequence SEQ]``: forget a capture registered with ``humancal add`` (or the inbox).

In this order, so that an interrupted removal can be run again and finishes the job:

1. the dataset (or one sequence) leaves the user datasets file ``<state dir>/datasets.yaml``, atomically
   (``humancal.datasets.sequences.remove_user_sequences``): from then on no command registers its partitions again;
2. its partitions ``NAME__SEQ`` leave the instance's dynamic partitions, and their materialization history is
   wiped (the Dagster UI no longer lists them);
3. its artifacts ``<state dir>/artifacts/*/NAME__SEQ.*`` are deleted (on a store too), and the fan-in tables that
   held its rows (``benchmark_table``, ``stage_timings``), which the next ``humancal update`` computes again
   without it;
4. the failures remembered for its partitions are forgotten.

Datasets that come with humancal (``synthetic``, ``shelf``, those of ``HUMANCAL_DATASETS``) are refused with a
message saying why. When ``NAME`` is no longer in the user datasets file but partitions or artifacts of it are
left (an interrupted removal), those are cleaned up.
"""

from __future__ import annotations

import sys

from upath import UPath

__all__ = ["cmd_remove"]

FAN_IN_TABLES = ("benchmark_table", "stage_timings")


def cmd_remove(args) -> int:
    from humancal.datasets.sequences import DatasetsConfigError, remove_user_sequences, user_config_path
    from humancal.settings import state_dir

    state = state_dir()
    try:
        keys = remove_user_sequences(args.name, args.sequence)
        print(f"removed {', '.join(keys)} from {user_config_path()}")
    except DatasetsConfigError as err:
        if "comes with humancal" in str(err):
            raise SystemExit(f"humancal: {err}") from None
        keys = _leftovers(state, args.name, args.sequence)
        if not keys:
            raise SystemExit(f"humancal: {err}") from None
        print(f"{args.name} is not in {user_config_path()}; removing what is left of it: {', '.join(keys)}")
    _forget_partitions(keys)
    deleted = _delete_artifacts(state / "artifacts", keys)
    from pipelines.failure_record import FailureRecord

    record = FailureRecord.in_state_dir(state)
    record.forget_partitions(set(keys))
    record.save()
    print(f"deleted {deleted} artifact file(s) under {state / 'artifacts'}")
    _mention_inbox(args.name)
    return 0


def _leftovers(state: UPath, name: str, sequence: str | None) -> list[str]:
    """Partition keys of ``name`` still registered in the instance or with artifacts (an interrupted removal)."""
    from pipelines import cli
    from pipelines.partitions import SEQUENCES

    def ours(key: str) -> bool:
        return key == f"{name}__{sequence}" if sequence else key.startswith(f"{name}__")

    keys = {k for k in cli._instance().get_dynamic_partitions(SEQUENCES.name) if ours(k)}
    artifacts = state / "artifacts"
    if artifacts.is_dir():
        keys |= {f.name.split(".", 1)[0] for f in artifacts.glob(f"*/{name}__*") if ours(f.name.split(".", 1)[0])}
    return sorted(keys)


def _forget_partitions(keys: list[str]) -> None:
    """Delete the partitions from the instance and wipe their materialization history."""
    from pipelines import cli
    from pipelines.partitions import SEQUENCES

    instance = cli._instance()
    registered = set(instance.get_dynamic_partitions(SEQUENCES.name))
    for key in keys:
        if key in registered:
            instance.delete_dynamic_partition(SEQUENCES.name, key)
    try:
        for asset_key in instance.all_asset_keys():
            instance.wipe_asset_partitions(asset_key, keys)
    except NotImplementedError:  # a storage that cannot wipe partitions: the history stays, harmlessly
        print("note: this instance's storage keeps the history of the removed partitions", file=sys.stderr)
    print(f"deleted partition(s) {', '.join(k for k in keys if k in registered) or 'none'} from the instance")


def _delete_artifacts(root: UPath, keys: list[str]) -> int:
    """Delete every artifact of ``keys`` (and leftover temporaries); the fan-in tables too when they held one."""
    if not root.is_dir():
        return 0
    files = [f for key in keys for pattern in (f"*/{key}.*", f"*/.{key}.*") for f in root.glob(pattern)]
    held_rows = any(f.parent.name == "metric_tables" for f in files)
    for f in files:
        f.unlink(missing_ok=True)
    if held_rows:
        fan_in = [root / f"{name}.parquet" for name in FAN_IN_TABLES if (root / f"{name}.parquet").exists()]
        for f in fan_in:
            f.unlink()
        if fan_in:
            print(f"deleted {', '.join(f.stem for f in fan_in)} (they held its rows): `humancal update` computes "
                  "them again without it")
    return len(files)


def _mention_inbox(name: str) -> None:
    from pipelines.sensors import inbox_dir

    drop = inbox_dir() / name
    if drop.is_dir():
        print(f"note: {drop} is still in the capture inbox; delete it, or the inbox sensor registers it again "
              "when it changes")
