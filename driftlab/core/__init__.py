"""DriftLab's computation: vehicle model, plants, controller, planner, episode loop, optimizer (no I/O).

numba caches each compiled function keyed on its own source file's timestamp, not on the modules it calls: a
change to the plant left the episode loop's cached kernel running the old plant, silently (seen twice while
developing the CommonRoad plants). Unless NUMBA_CACHE_DIR is set, the cache therefore lives in a folder named
after a hash of this package's sources, so that any change to any of them compiles afresh.

Solved results that many processes repeat are kept the same way (driftlab.core.results_cache): the only files this
package writes are these two caches of pure results.
"""

from __future__ import annotations

import hashlib
import os
import sys
from functools import lru_cache
from pathlib import Path


@lru_cache(maxsize=1)
def source_hash() -> str:
    """A hash of this package's sources (every ``.py`` under driftlab/core)."""
    digest = hashlib.sha256()
    root = Path(__file__).parent
    for path in sorted(root.rglob("*.py")):
        digest.update(path.relative_to(root).as_posix().encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def cache_folder(kind: str, name: str) -> str | None:
    """``$XDG_CACHE_HOME/driftlab/<kind>/<name>``, made if missing; None where no cache home is writable."""
    cache_home = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    folder = os.path.join(cache_home, "driftlab", kind, name)
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError:
        return None
    return folder


def _use_a_cache_per_source() -> None:
    if os.environ.get("NUMBA_CACHE_DIR"):
        return  # the user's (the Docker image sets one at build time)
    folder = cache_folder("numba", source_hash())
    if folder is None:
        return  # no writable cache home: numba's default, beside the sources
    os.environ["NUMBA_CACHE_DIR"] = folder  # worker processes inherit it
    if "numba" in sys.modules:  # imported before us: its config was read already
        sys.modules["numba"].config.CACHE_DIR = folder


_use_a_cache_per_source()
