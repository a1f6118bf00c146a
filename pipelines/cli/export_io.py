"""What the exports and the viewer share: the stored tables of a partition they read, and the one rule for where
they write.

One rule for every export: it refuses to write where something is already there (``--out`` names an existing
file, or a folder that is not empty) and says so, naming the path; ``--overwrite`` replaces what the export writes
there (other files in the folder stay). An ``--out`` that cannot be written (a read-only folder) is one line naming
the path, checked before anything is computed.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["check_out", "stored_table"]


def stored_table(asset: str, partition: str):
    """The stored table of an asset partition (exits with the command to run when it is not stored)."""
    import pandas as pd

    from pipelines.definitions import artifacts_root
    from resources.io_managers import partition_path

    path = partition_path(artifacts_root(), asset, partition)
    if not path.exists():
        raise SystemExit(f"humancal: {asset} of {partition} is not stored ({path}); run `humancal update --partition {partition}`")
    return pd.read_parquet(str(path))


def _writable_ancestor(path: Path) -> Path:
    """The nearest existing folder at or above ``path`` (where the export creates what is missing)."""
    folder = path if path.is_dir() else path.parent
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    return folder


def check_out(out: str | Path, overwrite: bool) -> Path:
    """Check ``--out`` before anything is computed: not an existing file or non-empty folder unless
    ``overwrite``, and writable.

    Raises:
        SystemExit: the path exists (without ``--overwrite``), or it cannot be written; one line naming it.
    """
    out = Path(out).expanduser()
    if out.exists() and not overwrite:
        if out.is_file() or any(out.iterdir()):
            what = "exists" if out.is_file() else "is a folder that is not empty"
            raise SystemExit(f"humancal: {out} {what}; pass --overwrite to replace what the export writes there, "
                             "or choose another --out")
    folder = _writable_ancestor(out)
    target = out if out.exists() else folder
    if not os.access(target, os.W_OK) or not os.access(folder, os.W_OK | os.X_OK):
        raise SystemExit(f"humancal: cannot write {target}: permission denied (or a read-only file system); "
                         "choose another --out or make it writable")
    return out
