"""A study: many runs that answer one question.

- seeds: one tuning job per seed, the same specification otherwise ("is this setting better, over seeds?").
- robustness: one theta scored on every cell of a cartesian grid of config values ("how far does this theta
  hold when the car changes?"), each cell with the seeds of robust evaluation.

Both validate once, here, before anything is stored; a bad value raises ConfigError naming its field.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Any

from driftlab.core.config import EpisodeConfig, Theta, config_to_dict
from driftlab.core.configure import apply_overrides, config_from_document
from driftlab.core.errors import ConfigError
from driftlab.core.limits import JOB_LIMITS, MAX_ROBUST_SAMPLES, check_int
from driftlab.core.robust import tuning_seeds
from driftlab.core.statuses import StudyKind
from driftlab.core.tuning import TuningSpec

MAX_STUDY_SEEDS = 32  # jobs in one seeds study
MAX_GRID_CELLS = 400  # cells in one robustness study


STUDY_KINDS = tuple(StudyKind)


@dataclass(frozen=True)
class SeedsStudySpec:
    """One job per seed of ``seeds``, each ``job`` with its own seed."""

    seeds: tuple[int, ...]
    job: TuningSpec

    def __post_init__(self) -> None:
        if not self.seeds:
            raise ConfigError(f"seeds must list 1 to {MAX_STUDY_SEEDS} distinct seeds, got none")
        if len(self.seeds) > MAX_STUDY_SEEDS:
            raise ConfigError(f"seeds must list 1 to {MAX_STUDY_SEEDS} distinct seeds, got {len(self.seeds)}")
        for i, seed in enumerate(self.seeds):
            lo, hi = JOB_LIMITS["seed"]
            check_int(f"seeds[{i}]", seed, lo, hi)
        duplicates = sorted({s for s in self.seeds if self.seeds.count(s) > 1})
        if duplicates:
            raise ConfigError(f"seeds must be distinct; repeated: {', '.join(map(str, duplicates))}")

    def job_specs(self) -> list[TuningSpec]:
        """The jobs' specifications, in the order of ``seeds``."""
        return [TuningSpec.from_dict({**self.job.to_dict(), "seed": seed}) for seed in self.seeds]

    def to_dict(self) -> dict[str, Any]:
        return {"kind": StudyKind.SEEDS, "seeds": list(self.seeds), "spec": self.job.to_dict()}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> SeedsStudySpec:
        seeds = data.get("seeds")
        if not isinstance(seeds, (list, tuple)):
            raise ConfigError(f"seeds must be a list of 1 to {MAX_STUDY_SEEDS} distinct seeds")
        spec = data.get("spec")
        if not isinstance(spec, dict):
            raise ConfigError("spec must be a job specification object (as POST /api/jobs takes)")
        try:
            job = TuningSpec.from_dict({k: v for k, v in spec.items() if k != "seed"})
        except ConfigError as exc:
            raise ConfigError(f"spec: {exc}") from None
        return cls(seeds=tuple(seeds), job=job)


def _grid_axes(grid: Any, base: EpisodeConfig) -> dict[str, tuple[Any, ...]]:
    """The grid's keys and values, each value checked by the config's own validation (errors name the key)."""
    if not isinstance(grid, dict) or not grid:
        raise ConfigError("grid must map 1 or more config keys (e.g. 'plant.friction_scale') to lists of values")
    axes = {}
    for key, values in grid.items():
        if not isinstance(values, (list, tuple)) or not values:
            raise ConfigError(f"grid.{key} must be a non-empty list of values")
        for value in values:
            try:
                apply_overrides(base, {key: value})
            except ConfigError as exc:
                raise ConfigError(f"grid.{key}: {exc}") from None
        if len(set(map(repr, values))) != len(values):
            raise ConfigError(f"grid.{key} repeats a value")
        axes[key] = tuple(values)
    cells = math.prod(len(v) for v in axes.values())
    if cells > MAX_GRID_CELLS:
        raise ConfigError(f"grid has {cells} cells; at most {MAX_GRID_CELLS} are allowed (1 to {MAX_GRID_CELLS})")
    return axes


@dataclass(frozen=True)
class RobustnessStudySpec:
    """``theta`` run on every cell of ``grid`` (config overrides on ``config``), each cell on the episode seeds
    ``tuning_seeds(seed, robust_samples)`` (the seeds of the job the theta came from, when it came from one).

    Attributes:
        theta: the theta scored.
        grid: dotted config key -> values; cells are their cartesian product, the first key varying slowest.
        config: the base episode configuration.
        robust_samples: seeded episodes per cell (1..64).
        seed: picks the episode seeds, as a job's seed does.
        evaluation_id: where theta came from, if it came from a stored evaluation.
    """

    theta: dict[str, float]
    grid: dict[str, tuple[Any, ...]]
    config: EpisodeConfig
    robust_samples: int = 1
    seed: int = 0
    evaluation_id: int | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "theta", Theta.from_mapping(self.theta).as_dict())
        check_int("robust_samples", self.robust_samples, 1, MAX_ROBUST_SAMPLES)
        check_int("seed", self.seed)
        object.__setattr__(self, "grid", _grid_axes(self.grid, self.config))

    @property
    def episode_seeds(self) -> list[int]:
        return tuning_seeds(self.seed, self.robust_samples)

    def cells(self) -> list[dict[str, Any]]:
        """Each cell's settings {key: value}, in a fixed order."""
        keys = list(self.grid)
        return [dict(zip(keys, values, strict=True)) for values in itertools.product(*self.grid.values())]

    def cell_episode_config(self, settings: dict[str, Any]) -> EpisodeConfig:
        return apply_overrides(self.config, settings)

    def cell_config(self, settings: dict[str, Any]) -> dict[str, Any]:
        """A cell's full episode configuration as a plain document (what the executor takes)."""
        return config_to_dict(self.cell_episode_config(settings))

    def to_dict(self) -> dict[str, Any]:
        return {"kind": StudyKind.ROBUSTNESS, "theta": self.theta, "grid": {k: list(v) for k, v in self.grid.items()},
                "config": config_to_dict(self.config), "robust_samples": self.robust_samples, "seed": self.seed,
                "evaluation_id": self.evaluation_id}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> RobustnessStudySpec:
        config = config_from_document(data.get("config"))
        theta = data.get("theta")
        if not isinstance(theta, dict):
            raise ConfigError("theta must be an object {c_lr, c_rl, dV, k}")
        return cls(theta=theta, grid=data.get("grid") or {}, config=config,
                   robust_samples=data.get("robust_samples", 1), seed=data.get("seed", 0),
                   evaluation_id=data.get("evaluation_id"))


def study_spec_from_dict(data: dict[str, Any]) -> SeedsStudySpec | RobustnessStudySpec:
    kind = data.get("kind")
    if kind == StudyKind.SEEDS:
        return SeedsStudySpec.from_dict(data)
    if kind == StudyKind.ROBUSTNESS:
        return RobustnessStudySpec.from_dict(data)
    raise ConfigError(f"kind must be one of {', '.join(STUDY_KINDS)}, got {kind!r}")


@dataclass(frozen=True)
class GridTable:
    """A robustness study's cells laid out as a table: rows are the first grid key's values, columns every
    combination of the others (one column when the grid has one key).

    Attributes:
        row_key: the first grid key; row_values its values.
        column_key: the other keys, comma-separated ("" for a one-key grid).
        column_labels: their values in each column, comma-separated ("" for a one-key grid).
        J: rows x columns, NaN where a cell is pending.
        status: rows x columns of the cells' statuses ("pending", "completed", or how it failed).
    """

    row_key: str
    row_values: tuple[Any, ...]
    column_key: str
    column_labels: tuple[str, ...]
    J: tuple[tuple[float, ...], ...]
    status: tuple[tuple[str, ...], ...]


def grid_table(grid: dict[str, list[Any]], cells: list[dict[str, Any]]) -> GridTable:
    """Cells (``{"index", "status", "J"}``, indexed in the cartesian order of :meth:`RobustnessStudySpec.cells`)
    as a :class:`GridTable`."""
    keys = list(grid)
    rest = [dict(zip(keys[1:], values, strict=True)) for values in itertools.product(*(grid[k] for k in keys[1:]))]
    n_columns = len(rest)
    by_index = {c["index"]: c for c in cells}
    values, statuses = [], []
    for r in range(len(grid[keys[0]])):
        row = [by_index.get(r * n_columns + c, {}) for c in range(n_columns)]
        values.append(tuple(math.nan if cell.get("J") is None else float(cell["J"]) for cell in row))
        statuses.append(tuple(cell.get("status", "pending") for cell in row))
    labels = tuple(", ".join(str(v) for v in combo.values()) for combo in rest)
    return GridTable(keys[0], tuple(grid[keys[0]]), ", ".join(keys[1:]), labels, tuple(values), tuple(statuses))
