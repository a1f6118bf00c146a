"""``humancal update`` and ``humancal demo``: bring asset partitions up to date, say what failed, and how out.

Both take the no-op shortcut first (:mod:`pipelines.update_stamp`): when nothing changed since the same command
last found nothing to do, they print what it printed and exit with its status, without loading the Definitions.

Output: the rounds as they run and ``materialized N asset partitions``; then one line per failing partition
(what failed, the message, the way out), one line per failed check, and a one-line reminder per partition that
failed in an earlier update and was not retried (nothing it depends on changed). With ``-v``, also what was left
waiting and why, and which partitions a fan-in table was computed without. The exit status
(:attr:`pipelines.update_result.UpdateResult.exit_status`): 1 when something failed in this update, or when a
partition named with ``--partition`` (``demo``: ``synthetic__demo``) is failed or held back; else 0.
"""

from __future__ import annotations

import time
from collections import defaultdict

from pipelines import cli
from pipelines.update_stamp import Output, fingerprint, replay, store

__all__ = ["cmd_demo", "cmd_update", "report"]


def _command_key(name: str, partitions: list[str] | None) -> str:
    return name + "".join(f" --partition {p}" for p in sorted(set(partitions or ())))


def cmd_update(args) -> int:
    verbose = bool(getattr(args, "verbose", False))
    key = _command_key("update", args.partition)
    status = replay(key, verbose)
    if status is not None:
        return status
    out = Output(verbose)
    return _update_and_report(out, key, args.partition or None, lambda result, out: None)


def cmd_demo(args) -> int:
    verbose = bool(getattr(args, "verbose", False))
    key = _command_key("demo --all" if getattr(args, "all", False) else "demo", None)
    status = replay(key, verbose)
    if status is not None:
        return status
    out = Output(verbose)
    out(f"humancal demo: materializing what {cli.DEMO_PARTITION} needs (the first run builds the body model's "
        "cache, about a minute; later runs reuse it) ...")
    return _update_and_report(out, key, [cli.DEMO_PARTITION], lambda result, out: _demo_table(out, result, args))


def _update_and_report(out: Output, key: str, partitions: list[str] | None, after) -> int:
    """Run the update, print its report (then ``after(result, out)``, which may print more and override the
    status), and record the output for the shortcut when nothing was left to do."""
    from humancal.settings import state_dir
    from pipelines.cluster import ClusterSettings
    from pipelines.definitions import defs
    from pipelines.failure_record import FailureRecord
    from pipelines.quiet_warp import init_warp_quietly
    from pipelines.update import update

    instance = cli._instance()
    cli.register_partitions(instance, defs)
    if not key.startswith("demo"):
        cli._check_partitions(partitions, defs)
    cli._print_active_lifter(out)
    exclude = [*cli._report_missing_data(defs, out), *cli._assets_on_request(defs)]
    prefix = list(out.lines)
    shortcut = _is_persistent(instance)
    before = fingerprint(key) if shortcut else None
    failures = FailureRecord.in_state_dir(state_dir())
    cluster = ClusterSettings.from_env()
    if cluster is not None:
        from pipelines.cluster import answering_workers

        workers = answering_workers(cluster)
        out(f"steps run on the Celery workers of {cluster.broker_url} (humancal worker); the runs of a round at once")
        if workers:
            out(f"{len(workers)} worker(s) answered: {', '.join(workers)}")
        else:
            out("no worker answered within 3 s (none started, or every one busy with a step): the steps wait on the "
                "broker until a `humancal worker` with the same HUMANCAL_* settings takes them", "err")
    t0 = time.perf_counter()

    def run():
        return update(defs, instance, partitions=partitions, exclude=exclude, on_round=_round_printer(out),
                      run_config=_run_config(out.verbose), failures=failures, before_run=init_warp_quietly,
                      cluster=cluster, on_run_done=_run_printer(out) if cluster is not None else None,
                      on_stored=_stored_printer(out) if cluster is None else None)

    result = run()
    out(f"materialized {result.count} asset partitions" + (f" in {time.perf_counter() - t0:.1f} s" if result.count else ""))
    status = _finish(result, out, after)
    if not shortcut or result.failed_now:
        return status
    if result.count:  # confirm that nothing is left: the output a no-op would print, for the shortcut
        before, quiet = fingerprint(key), Output(out.verbose, echo=False)
        quiet.lines = list(prefix)
        confirm = run()
        if confirm.count:  # something changed meanwhile (another process): say what this pass did
            out(f"materialized {confirm.count} more asset partitions")
            return max(status, _finish(confirm, out, lambda result, out: None))
        quiet("materialized 0 asset partitions")
        store(key, before, quiet, _finish(confirm, quiet, after))
    else:
        store(key, before, out, status)
    return status


def _finish(result, out: Output, after) -> int:
    status = report(result, out)
    override = after(result, out)
    return status if override is None else override


def _is_persistent(instance) -> bool:
    """The instance of the local dir (not a test's in-memory one): only then does the shortcut apply."""
    from pathlib import Path

    from humancal.settings import local_dir

    root = getattr(instance, "root_directory", None)
    return root is not None and Path(root).resolve() == (local_dir() / "dagster_home").resolve()


def _run_config(verbose: bool) -> dict:
    """Dagster's console log: everything from INFO with ``-v``; otherwise nothing (a failure's traceback is in the
    run's log in the Dagster UI and under ``-v``; the update prints one line per failing partition)."""
    return {"loggers": {"console": {"config": {"log_level": "INFO" if verbose else "CRITICAL"}}}}


def _round_printer(out: Output):
    def print_round(n, items) -> None:
        names = ", ".join(f"{k.to_user_string()}[{p}]" if p else k.to_user_string() for k, p in items)
        out(f"round {n}: {len(items)} stale or missing: {names}")

    return print_round


def _stored_printer(out: Output):
    def print_stored(key, partition, seconds) -> None:
        name = f"{key.to_user_string()}[{partition}]" if partition else key.to_user_string()
        out(f"  stored {name} ({seconds:.0f} s into the round)")

    return print_stored


def _run_printer(out: Output):
    def print_run(partition, success, ended, total) -> None:
        out(f"  run {ended}/{total} ended: {partition or 'shared assets'}{'' if success else ' (failed)'}")

    return print_run


def _user_datasets() -> set[str]:
    from humancal.datasets.sequences import load_datasets_config, user_config_path

    user = str(user_config_path())
    try:
        return {spec.dataset for spec in load_datasets_config().values() if spec.source == user}
    except ValueError:
        return set()


def way_out(partition: str | None, user_datasets: set[str]) -> str:
    """What the user can do about a failing partition."""
    if partition is None:
        return "after a fix, `humancal update` retries it"
    dataset = partition.split("__", 1)[0]
    retry = f"`humancal update --partition {partition}` retries it"
    if dataset in user_datasets:
        return f"fix the capture, then {retry}; or `humancal remove {dataset}`"
    return f"after a fix, {retry}"


def report(result, out: Output) -> int:
    """Print what was left (``-v``), what failed, the failed checks and the reminders; returns the exit status."""
    for line in result.waiting_lines():
        out(line, verbose=True)
    for line in result.left_out_lines():
        out(line, verbose=True)
    users = _user_datasets() if result.failed or result.earlier_failed or result.checks else set()
    for partition, what in _by_partition((p, a, m) for a, p, m in result.failed).items():
        out(f"FAILED {partition or 'shared asset'}: {what} ({way_out(partition, users)})", "err")
    _print_failed_checks(result, out, users)
    earlier = _by_partition((f.partition, f.asset, f.message) for f in result.earlier_failed)
    when = {f.partition: f.when_text for f in result.earlier_failed}
    for partition, what in earlier.items():
        out(f"reminder: {partition or 'a shared asset'} failed in an earlier update ({when[partition]}) and nothing "
            f"it depends on changed since, so it was not retried: {what} ({way_out(partition, users)})", "err")
    return result.exit_status


def _by_partition(failures) -> dict[str | None, str]:
    """``(partition, asset, message)`` -> per partition, what failed: the message (which names the step), prefixed
    with the assets when it does not name them (the outputs of one step share its message)."""
    assets: dict[str | None, dict[str, list[str]]] = defaultdict(lambda: defaultdict(list))
    for partition, asset, message in failures:
        assets[partition][message].append(asset)
    return {partition: "; ".join(m if any(m.startswith(f"{a}:") for a in names) else f"{', '.join(names)}: {m}"
                                 for m, names in messages.items())
            for partition, messages in assets.items()}


def _print_failed_checks(result, out: Output, users: set[str]) -> None:
    """ERROR: a blocking check failed (what depends on it was not computed); WARN: a warning; ERROR (not
    blocking): a failed check that does not protect anything downstream. The check's description says what to
    fix; a user's capture can also be removed."""
    for outcome in result.checks:
        label = "ERROR" if outcome.blocks else "WARN" if outcome.severity == "WARN" else "ERROR (not blocking)"
        when = " (evaluated by an earlier run)" if outcome in result.earlier_checks else ""
        dataset = (outcome.partition or "").split("__", 1)[0]
        hint = f" (or `humancal remove {dataset}`)" if outcome.blocks and dataset in users else ""
        out(f"{label} {outcome.where} {outcome.check}{when}: {outcome.description}{hint}", "err")


def _demo_table(out: Output, result, args) -> int | None:
    """The demo's figures after the update: the headline table (every headline row with ``--all``)."""
    from pipelines.cli.headline import headline_lines

    if result.exit_status:
        if result.blocking_failed:
            # Not the stored table: it was computed by an earlier run, from other cameras, and would read as if all
            # were fine.
            out(f"no metric table: a blocking check failed, so metric_tables[{cli.DEMO_PARTITION}] was not computed "
                "from these cameras (a table stored by an earlier run describes other ones: `humancal report`)", "err")
        return None
    out("")
    for line in headline_lines(cli.DEMO_PARTITION, everything=bool(getattr(args, "all", False))):
        out(line)
    return None
