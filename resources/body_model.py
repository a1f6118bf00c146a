"""The body model as a Dagster resource (one anny instance per process)."""

from __future__ import annotations

import functools

import dagster as dg

from humancal.settings import anny_cache_dir


@functools.lru_cache(maxsize=4)
def _load(cache_dir: str, device: str):
    from humancal.body import BodyModel

    return BodyModel(cache_dir=cache_dir, device=device)


class BodyModelResource(dg.ConfigurableResource):
    """anny in float32, with its cache in the project's state folder unless ``cache_dir`` says otherwise.

    The first construction on a fresh machine builds anny's cache (about a minute, ~790 MB).
    """

    cache_dir: str | None = None
    device: str = "cpu"

    def get(self):
        """The shared :class:`humancal.body.BodyModel` of this process."""
        return _load(self.cache_dir or str(anny_cache_dir()), self.device)
