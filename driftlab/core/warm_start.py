"""A job's warm start: what it takes from other jobs' evaluations before its own first one.

Two ways, chosen per source job. A source that ran the same episode configuration (plant, controller, scenario,
failure limits: the same J) is a run of the same problem: its evaluations are told to the new job's optimizer
before the job's own, so the GP starts where the source left off and the space-filling design is skipped (a job
over the same config is a continuation). A source of another configuration (the same car at another sideslip,
another plant) measured another J surface: its values are not told, its best thetas are asked first (the initial
design), where the GP then learns the new surface from the new job's own evaluations. A prior (the source's GP
mean as the new GP's mean) would transfer the shape too, but J's level moves between scenarios, and a wrong
prior misleads the search for longer than a few wasted initial points do.

The resolved start is stored with the job (the source job ids and what was taken from them), so a job re-runs
from its own document even after its sources are deleted.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from driftlab.core.config import Theta
from driftlab.core.errors import ConfigError

# Of a source of another configuration, its best completed thetas asked first (each a distinct evaluation).
WARM_POINTS = 5
MAX_WARM_JOBS = 20


@dataclass(frozen=True)
class Observation:
    """One evaluation told to the optimizer: theta, J if it completed (None: failed), and the J stored."""

    theta: dict[str, float]
    value: float | None
    stored_j: float

    def as_list(self) -> list[Any]:
        return [self.theta, self.value, self.stored_j]


@dataclass(frozen=True)
class SourceJob:
    """A finished or running job a new one may start from: its id, its episode config (as stored) and its
    evaluations (theta, J, completed), in index order."""

    job_id: int
    config: dict[str, Any]
    evaluations: Sequence[tuple[Mapping[str, float], float, bool]]


@dataclass(frozen=True)
class WarmStart:
    """What a job starts from: ``told`` evaluations of jobs of its own config, ``initial_points`` asked first (best
    thetas of jobs of another config, then the theta its car profile's weights were found with), per source job how
    it was used (``"told"`` or ``"initial"``), and the car profile whose theta it asks (``from_profile``)."""

    from_jobs: dict[int, str]
    told: tuple[Observation, ...] = ()
    initial_points: tuple[dict[str, float], ...] = ()
    from_profile: int | None = None

    def to_dict(self) -> dict[str, Any]:
        out = {"from_jobs": [{"job_id": k, "used_as": v} for k, v in self.from_jobs.items()],
               "told": [o.as_list() for o in self.told], "initial_points": [dict(p) for p in self.initial_points]}
        return out if self.from_profile is None else {**out, "from_profile": self.from_profile}

    def joined(self, other: WarmStart) -> WarmStart:
        """Both starts: ``other``'s sources and points after this one's."""
        points = [*self.initial_points, *(p for p in other.initial_points if p not in self.initial_points)]
        return WarmStart({**self.from_jobs, **other.from_jobs}, self.told + other.told, tuple(points),
                         self.from_profile if other.from_profile is None else other.from_profile)

    def best_told(self) -> dict[str, Any] | None:
        """The best completed evaluation it told (a job continued from jobs of its own config starts from it, and
        shows it as its best told): {"theta", "J", "from_jobs"}; None if it told none that completed."""
        done = [o for o in self.told if o.value is not None]
        if not done:
            return None
        best = min(done, key=lambda o: o.stored_j)
        return {"theta": best.theta, "J": best.stored_j,
                "from_jobs": [job_id for job_id, used in self.from_jobs.items() if used == "told"]}

    def check(self, bounds: Mapping[str, tuple[float, float]]) -> None:
        """Raise ConfigError unless every theta it holds names each key of ``bounds``, each initial point inside."""
        for observation in self.told:
            if any(k not in observation.theta for k in bounds):
                raise ConfigError("warm_start.told: each theta needs every key of the bounds", field="warm_start")
        if not all(_inside(p, bounds) for p in self.initial_points):
            raise ConfigError("warm_start.initial_points must lie inside the bounds", field="warm_start")

    @classmethod
    def from_dict(cls, data: Any) -> WarmStart:
        if not isinstance(data, dict):
            raise ConfigError("warm_start must be an object", field="warm_start")
        try:
            return cls(from_jobs={int(s["job_id"]): str(s["used_as"]) for s in data.get("from_jobs", [])},
                       told=tuple(Observation(dict(t), None if v is None else float(v), float(j))
                                  for t, v, j in data.get("told", [])),
                       initial_points=tuple(dict(p) for p in data.get("initial_points", [])),
                       from_profile=None if data.get("from_profile") is None else int(data["from_profile"]))
        except (KeyError, TypeError, ValueError):
            raise ConfigError("warm_start must be {from_jobs: [{job_id, used_as}], told: [[theta, J or null, J]], "
                              "initial_points: [theta]}", field="warm_start") from None


def warm_start(sources: Sequence[SourceJob], config: dict[str, Any], bounds: Mapping[str, tuple[float, float]],
               points: int = WARM_POINTS) -> WarmStart:
    """The start a job of episode ``config`` (as stored) and search box ``bounds`` takes from ``sources``: see the
    module docstring. Thetas outside the box are left out (told) or moved onto its faces (initial points)."""
    if not 1 <= len(sources) <= MAX_WARM_JOBS:
        raise ConfigError(f"warm_start_from: give 1 to {MAX_WARM_JOBS} job ids", field="warm_start_from")
    used, told, initial = {}, [], []
    for source in sources:
        if source.config == config:
            used[source.job_id] = "told"
            told += [Observation(_theta(t, bounds), j if done and math.isfinite(j) else None, j)
                     for t, j, done in source.evaluations if _inside(t, bounds)]
            continue
        used[source.job_id] = "initial"
        ranked = sorted((j, i) for i, (_, j, done) in enumerate(source.evaluations) if done and math.isfinite(j))
        initial += [_clipped(source.evaluations[i][0], bounds) for _, i in ranked[:points]]
    unique = [p for n, p in enumerate(initial) if p not in initial[:n]]
    return WarmStart(used, tuple(told), tuple(unique))


def profile_start(profile_id: int, theta: Mapping[str, float] | str | None,
                  bounds: Mapping[str, tuple[float, float]]) -> WarmStart | None:
    """The start a job takes from its car profile (driftlab calibrate): the theta the profile's weights were
    searched with, asked first, where it is not the untuned theta the job asks anyway. A calibration's later round
    searches the weights for the theta a job learned with the last round's (a CommonRoad BMW at 0.55 rad: k on
    its bound, -0.12), and those weights may drive little else; a job that does not meet that theta early may never
    complete an episode there. ``theta``: as the profile stores it ("untuned", or None before it was stored)."""
    if not isinstance(theta, Mapping):
        return None
    point = _clipped(theta, bounds)
    if point == _clipped({}, bounds):
        return None
    return WarmStart({}, (), (point,), profile_id)


def _theta(theta: Mapping[str, float], bounds: Mapping[str, tuple[float, float]]) -> dict[str, float]:
    return {k: float(theta[k]) for k in bounds}


def _inside(theta: Mapping[str, float], bounds: Mapping[str, tuple[float, float]]) -> bool:
    return all(k in theta and lo <= float(theta[k]) <= hi for k, (lo, hi) in bounds.items())


def _clipped(theta: Mapping[str, float], bounds: Mapping[str, tuple[float, float]]) -> dict[str, float]:
    """Theta in the box; a key the source did not learn is what it ran with, the untuned value."""
    full = Theta.filled(theta)
    return {k: min(max(float(full[k]), lo), hi) for k, (lo, hi) in bounds.items()}
