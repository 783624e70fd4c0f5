"""Where episodes run: one small interface (``episode``), a local process pool (``local``) or a Dask cluster
(``dask_cluster``).

A distributed engine (Dask's ``Client.submit`` returns compatible futures) can take the place of
:class:`LocalProcessExecutor` by implementing :class:`EpisodeExecutor`.
"""

from __future__ import annotations

from driftlab.worker.executors.episode import EpisodeExecutor, EpisodeOutcome, evaluate_episode
from driftlab.worker.executors.local import LocalProcessExecutor

__all__ = ["EpisodeExecutor", "EpisodeOutcome", "LocalProcessExecutor", "evaluate_episode", "open_executor"]


def open_executor(workers: int | None, dask_address: str | None = None, *, niceness: int = 0
                  ) -> tuple[EpisodeExecutor, int]:
    """The local process pool, or a Dask cluster by address; and how many episodes to keep in flight (given,
    or the cluster's worker threads; 1 locally by default)."""
    if dask_address:
        from driftlab.worker.executors.dask_cluster import DaskExecutor

        executor = DaskExecutor(dask_address)
        return executor, workers or executor.workers
    return LocalProcessExecutor(workers or 1, niceness=niceness), workers or 1
