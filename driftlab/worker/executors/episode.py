"""What an executor runs and returns: one episode of (theta, config, seed), and the interface every executor
implements (submit -> Future, shutdown)."""

from __future__ import annotations

import json
import math
from concurrent.futures import Future
from dataclasses import dataclass
from functools import cached_property, lru_cache
from typing import Any, Protocol

import numpy as np

from driftlab.core.robust import SampleResult, phase_errors
from driftlab.core.statuses import EpisodeStatus
from driftlab.db.trajectory_bytes import PackedTrajectory


@dataclass
class EpisodeOutcome:
    """What a worker process sends back: everything storage needs, as plain data."""

    theta: dict[str, float]
    seed: int
    status: str
    J: float
    metrics: dict[str, Any]
    trigger_points: list[dict[str, float]]
    wall_ms: float
    columns: list[str]
    packed: PackedTrajectory  # packed where the episode ran: the server stores the bytes as they come

    @classmethod
    def packing(cls, *, trajectory: np.ndarray, **fields: Any) -> EpisodeOutcome:
        return cls(packed=PackedTrajectory.of(trajectory), **fields)

    @property
    def trajectory(self) -> np.ndarray:
        return self.packed.array(len(self.columns))

    @property
    def completed(self) -> bool:
        return self.status == EpisodeStatus.COMPLETED

    @cached_property
    def sample(self) -> SampleResult:
        """This episode as one sample of a robust evaluation (read once: a job scores an evaluation again when it
        asks for confirmation seeds)."""
        error = self.metrics.get("mean_abs_e_m")
        validity = self.metrics.get("plant_validity") or {}
        negative, one_side = validity.get("negative_wheel_load_s"), validity.get("one_side_off_s")
        by_phase = phase_errors(self.metrics.get("phases") or [])
        return SampleResult(self.seed, self.status, float(self.J), float(self.metrics.get("completed_fraction", 0.0)),
                            float(error) if error is not None and math.isfinite(error) else None,
                            None if negative is None else float(negative),
                            None if one_side is None else float(one_side), drift=by_phase.get("drift"),
                            flick=by_phase.get("flick"))


class EpisodeExecutor(Protocol):
    def submit(self, theta: dict[str, float], config_doc: dict[str, Any], seed: int = 0) -> Future[EpisodeOutcome]:
        ...

    def shutdown(self) -> None: ...


@lru_cache(maxsize=16)
def _config_of(config_json: str):
    """The validated config of a job's document, parsed (and fitted, where a what-if or a robustness study's cell
    sends it still to be fitted) once per worker process: every episode of a job sends the same document (parsing
    it: ~0.4 ms of a ~17 ms default episode; the key: ~0.03 ms). EpisodeConfig is frozen."""
    from driftlab.core.configure import config_from_dict, fitted

    return fitted(config_from_dict(json.loads(config_json)))


def evaluate_episode(theta: dict[str, float], config_doc: dict[str, Any], seed: int = 0) -> EpisodeOutcome:
    """Runs in the worker process. A pure function of its arguments (see run_episode)."""
    from driftlab.core.config import Theta
    from driftlab.core.episode import COLUMNS, run_episode

    config = _config_of(json.dumps(config_doc))  # key order kept: dotted keys apply in order
    result = run_episode(Theta.from_mapping(theta), config, seed=seed)
    return EpisodeOutcome.packing(theta=dict(theta), seed=seed, status=result.status, J=float(result.J),
                                  metrics=result.metrics.as_dict(), trigger_points=result.trigger_points,
                                  wall_ms=float(result.wall_ms), columns=list(COLUMNS), trajectory=result.trajectory)
