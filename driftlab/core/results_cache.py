"""Solved results kept on disk for every process: a pure, deterministic solve that many processes repeat (a CommonRoad
car's drift family, the controller model's fit to it) is done once, and the CLI, the server and a calibration's
checks read its answer.

joblib.Memory keys each call by its arguments' contents (a car's packed parameters, a catalog entry's state) and keeps
the answer in ``$XDG_CACHE_HOME/driftlab/solved/<folder>``, one folder per hash of driftlab.core's sources and per
release of NumPy, SciPy and CommonRoad's vehicle models: a changed residual, solver or car never reads another's
answers. The floats come back as they were solved (pickled). With no writable cache home nothing is kept.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache, lru_cache, wraps
from importlib import metadata
from typing import Any, TypeVar

from driftlab.core import cache_folder, source_hash

Solve = TypeVar("Solve", bound=Callable[..., Any])


def kept_on_disk(solve: Solve) -> Solve:
    """``solve`` memoized in the results cache. joblib is loaded at the first call: a process that solves nothing
    imports none of it."""
    @wraps(solve)
    def call(*args: Any) -> Any:
        return _memoized(solve)(*args)

    return call  # type: ignore[return-value]


@cache
def _memoized(solve: Callable[..., Any]) -> Callable[..., Any]:
    from joblib import Memory

    return Memory(_folder(), verbose=0).cache(solve)


@lru_cache(maxsize=1)
def _folder() -> str | None:
    return cache_folder("solved", f"{source_hash()}-{'-'.join(_releases())}")


def _releases() -> list[str]:
    found = []
    for package in ("numpy", "scipy", "commonroad-vehicle-models"):
        try:
            found.append(f"{package}{metadata.version(package)}")
        except metadata.PackageNotFoundError:
            found.append(f"no-{package}")
    return found
