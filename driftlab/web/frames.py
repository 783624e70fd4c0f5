"""Stored episodes prepared for drawing: columns by name and frame lookup by time.

Only look-ups and colour maps live here; every number drawn comes from a trajectory the worker computed.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from driftlab.core.metrics import laps_of_rows
from driftlab.core.planner import Phase
from driftlab.core.track import FigureEight

# Sideslip colour map: beta < 0 (the drifts on the left, counter-clockwise circle) blue, grip grey,
# beta > 0 (the right, clockwise circle) red; saturated at |beta| = 0.4 rad, the paper's drift sideslip.
_SIDESLIP_ANCHORS_RAD = np.array([-0.4, 0.0, 0.4])
_SIDESLIP_COLORS_RGB = np.array([[20, 90, 230], [150, 150, 150], [225, 30, 30]], dtype=float)


def sideslip_colors(sideslip_rad: np.ndarray) -> np.ndarray:
    """RGB in [0, 255] (uint8) for each sideslip angle."""
    beta = np.asarray(sideslip_rad, dtype=float)
    channels = [np.interp(beta, _SIDESLIP_ANCHORS_RAD, _SIDESLIP_COLORS_RGB[:, i]) for i in range(3)]
    return np.stack(channels, axis=-1).astype(np.uint8)


@dataclass(frozen=True)
class EpisodeFrames:
    """One episode's trajectory rows (at the controller rate) with what the view labels it with."""

    columns: tuple[str, ...]
    rows: np.ndarray
    trigger_points: tuple[dict[str, Any], ...] = ()
    evaluation_id: int | None = None
    index: int | None = None
    theta: dict[str, float] = field(default_factory=dict)
    status: str = ""
    J: float = float("nan")  # a stored evaluation's J: the mean over its seeds; a what-if episode's own J
    seed: int | None = None  # the seed of the episode drawn (a stored evaluation's worst seed)
    episode_J: float = float("nan")  # J of the episode drawn, on ``seed``
    n_seeds: int = 1  # how many episodes J averages
    plant: dict[str, float] = field(default_factory=dict)  # plant settings a what-if episode changed
    failure_reason: str = ""  # why an episode stopped before its first step (its metrics')
    job: str = ""  # the stored evaluation's job: "job 3 · name"
    car: str = ""  # the plant it ran on (driftlab.services.read_model.plant_label)
    label: str = ""  # an episode not stored: what ran it (`driftlab episode --html`: its controller)

    def __post_init__(self) -> None:
        if self.rows.ndim != 2 or self.rows.shape[1] != len(self.columns):
            raise ValueError(f"rows must be (n, {len(self.columns)}), got {self.rows.shape}")

    def column(self, name: str) -> np.ndarray:
        return self.rows[:, self.columns.index(name)]

    @property
    def n_frames(self) -> int:
        return self.rows.shape[0]

    @property
    def duration_s(self) -> float:
        return float(self.column("t_s")[-1]) if self.n_frames else 0.0

    def index_at(self, t_s: float) -> int:
        """The last row at or before ``t_s`` (clamped to the episode)."""
        if self.n_frames == 0:
            raise ValueError("an empty trajectory has no frames")
        i = int(np.searchsorted(self.column("t_s"), t_s, side="right")) - 1
        return min(max(i, 0), self.n_frames - 1)

    def pose_at(self, i: int) -> tuple[float, float, float, float]:
        """(x [m], y [m], psi [rad], applied steering [rad]) of row i."""
        row = self.rows[i]
        c = self.columns.index
        return (float(row[c("x_m")]), float(row[c("y_m")]), float(row[c("psi_rad")]), float(row[c("delta_rad")]))

    def course_at(self, i: int) -> float:
        """Direction of travel psi + beta of row i [rad]."""
        return float(self.rows[i, self.columns.index("psi_rad")] + self.rows[i, self.columns.index("beta_rad")])

    def tracked_circle_at(self, i: int) -> int:
        """The circle tracked in row i: LEFT (+1) or RIGHT (-1), from the planner's phase."""
        return Phase(int(self.rows[i, self.columns.index("phase")])).direction

    def laps_on(self, track: FigureEight) -> np.ndarray:
        """The lap (1, 2, ...) of ``track`` each row is on, as the downloads' ``lap`` column."""
        return laps_of_rows(self.rows, {name: i for i, name in enumerate(self.columns)}, track)

    def triggers_before(self, t_s: float) -> list[dict[str, Any]]:
        return [p for p in self.trigger_points if p["t_s"] <= t_s]

    def name(self) -> str:
        """Which episode: the API's evaluation id first (what the URLs use), the job's index beside it."""
        if self.evaluation_id is None:
            return self.label or "what-if episode"
        job = f"{self.job} · " if self.job else ""
        return f"{job}evaluation id {self.evaluation_id} (index {self.index} in its job)"

    def j_text(self) -> str:
        """What J is: one episode on its seed, or a mean over seeds with the drawn episode's own J beside it."""
        if self.n_seeds <= 1:
            seed = "" if self.seed is None else f", seed {self.seed}"
            return f"J {self.J:.4g} (one episode{seed}; lower is better)"
        return (f"J {self.J:.4g} (mean of {self.n_seeds} seeds; lower is better); episode drawn: seed {self.seed}, "
                f"J {self.episode_J:.4g}")

    def caption(self) -> str:
        theta = ", ".join(f"{k} {v:.4g}" for k, v in self.theta.items())  # full precision: the downloads and the API
        plant = " | plant: " + ", ".join(f"{k} {v:.4g}" for k, v in self.plant.items()) if self.plant else ""
        car = f" | on {self.car}" if self.car else ""
        return f"{self.name()}: {self.status}, {self.j_text()} | {theta}{plant}{car}"


def frames_of_result(columns: tuple[str, ...], result: Any, label: str) -> EpisodeFrames:
    """An episode run here (a driftlab.core.episode.EpisodeResult with its trajectory's ``columns``), not stored,
    named ``label``."""
    return EpisodeFrames(tuple(columns), np.asarray(result.trajectory), tuple(result.trigger_points),
                         theta=result.theta.as_dict(), status=result.status, J=float(result.J), seed=int(result.seed),
                         episode_J=float(result.J), label=label)
