"""Initialise NVIDIA warp without its two start-up messages on a machine without a GPU.

anny's skinning (and ``evaluation.contact_metrics``) initialise warp (``wp.init()``) when first used. warp then
prints a banner ("Warp 1.19.0 initialized: ...") and, on a machine without the CUDA driver, the line "Warp CUDA
warning: Could not find or load the NVIDIA CUDA driver. GPU execution will not be available.". The banner obeys
``warp.config.log_level`` (warp's supported setting; ``warp.config.quiet`` in older releases); the CUDA line is
printed by warp's native library straight to file descriptor 2, whatever the configuration. So humancal
initialises warp itself before anything else does, with ``log_level`` at warnings and file descriptor 2 captured
for the duration of ``wp.init()``: the CUDA-driver line goes to the log (debug level, shown by ``humancal -v``),
anything else warp printed goes to stderr as before. ``wp.init()`` runs once per process, so the later calls of
anny and of the contact metrics print nothing.

Called by the commands that build the body model (``humancal update`` / ``demo`` before the first run,
``humancal export motions``); ``humancal.body`` is not touched.
"""

from __future__ import annotations

import logging
import os
import sys
import tempfile

__all__ = ["init_warp_quietly"]

log = logging.getLogger(__name__)

NO_DRIVER = "Could not find or load the NVIDIA CUDA driver"


def init_warp_quietly() -> None:
    """Initialise warp once, keeping its banner and its no-CUDA-driver warning off the terminal."""
    try:
        import warp as wp
    except ImportError:  # warp is a dependency of anny's skinning only
        return
    if getattr(wp.config, "log_level", None) is not None and hasattr(wp, "LOG_WARNING"):
        wp.config.log_level = max(wp.config.log_level, wp.LOG_WARNING)
    else:
        wp.config.quiet = True
    sys.stderr.flush()
    with tempfile.TemporaryFile(mode="w+b") as captured:
        saved = os.dup(2)
        os.dup2(captured.fileno(), 2)
        try:
            wp.init()
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
        captured.seek(0)
        text = captured.read().decode(errors="replace")
    for line in text.splitlines():
        if NO_DRIVER in line:
            log.debug("warp: %s", line.strip())
        elif line.strip():
            print(line, file=sys.stderr)
