"""The paper's figures (Fig. 4 and 5) from an episode trajectory; an edge module, outside core/."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Protocol

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import ListedColormap  # noqa: E402

from driftlab.core.convergence import best_so_far
from driftlab.core.metrics import laps_of_rows  # noqa: E402
from driftlab.core.statuses import EpisodeStatus
from driftlab.core.track import FigureEight  # noqa: E402


def _draw_track(ax, track: FigureEight) -> None:
    angles = np.linspace(0.0, 2.0 * math.pi, 361)
    for circle, colour in ((track.left, "tab:blue"), (track.right, "tab:green")):
        ax.plot(circle.center_x_m + circle.radius_m * np.cos(angles),
                circle.center_y_m + circle.radius_m * np.sin(angles), "--", color=colour, lw=1, alpha=0.6)
    ax.plot([0.0], [0.0], "ko", ms=4, label="P0")


class PlottedEpisode(Protocol):
    """An episode as run (driftlab.core.episode.EpisodeResult) or as stored (driftlab.services.read_model)."""

    status: str
    J: float
    trajectory: np.ndarray
    trigger_points: Any

    @property
    def column_index(self) -> dict[str, int]: ...

    def column(self, name: str) -> np.ndarray: ...


def plot_episode(result: PlottedEpisode, track: FigureEight, path: str | Path, title: str = "",
                 lap_errors_m: Sequence[float] = ()) -> None:
    """x-y path with both circles and trigger points (each lap's mean |e| from ``lap_errors_m``), and V, beta, r,
    delta against references."""
    fig = plt.figure(figsize=(13, 8))
    grid = fig.add_gridspec(4, 2, width_ratios=[1.1, 1.4])
    ax_xy = fig.add_subplot(grid[:, 0])
    _draw_track(ax_xy, track)
    x, y = result.column("x_m"), result.column("y_m")
    if track.laps == 1:
        ax_xy.plot(x, y, color="tab:red", lw=1.5, label="path")
    else:  # one colour a lap: whether the drift stays where it was or wanders off
        lap = laps_of_rows(result.trajectory, result.column_index, track) - 1
        errors = lap_errors_m
        for i, colour in zip(range(track.laps), plt.cm.autumn(np.linspace(0.0, 0.7, track.laps)), strict=True):
            on_lap = lap == i
            if on_lap.any():
                mean_e = f", mean |e| {errors[i]:.2f} m" if i < len(errors) else ""
                ax_xy.plot(x[on_lap], y[on_lap], color=colour, lw=1.2, label=f"lap {i + 1}{mean_e}")
    for i, trig in enumerate(result.trigger_points):
        ax_xy.plot(trig["x_m"], trig["y_m"], "o", color="tab:orange", ms=8, label="trigger" if i == 0 else None)
    ax_xy.set_aspect("equal")
    ax_xy.set_xlabel("x [m]")
    ax_xy.set_ylabel("y [m]")
    ax_xy.legend(loc="upper right", fontsize=8)
    # Over the whole figure: a long title (theta at full precision) above the narrow x-y axes ran off its left.
    fig.suptitle(title or f"{result.status}, J = {result.J:.3f}", fontsize=9, parse_math=False)
    t = result.column("t_s")
    panels = (("V_mps", "V_ref_mps", "V [m/s]"), ("beta_rad", "beta_ref_rad", "beta [rad]"),
              ("r_radps", "r_ref_radps", "r [rad/s]"), ("delta_rad", "delta_ref_rad", "delta [rad]"))
    for row, (name, ref, label) in enumerate(panels):
        ax = fig.add_subplot(grid[row, 1])
        ax.plot(t, result.column(ref), "k--", lw=1, label="reference")
        ax.plot(t, result.column(name), color="tab:blue", lw=1.3, label="actual")
        for trig in result.trigger_points:
            ax.axvline(trig["t_s"], color="tab:orange", lw=1)
        ax.set_ylabel(label)
        if row == 0:
            ax.legend(loc="lower right", fontsize=8)
        if row == len(panels) - 1:
            ax.set_xlabel("t [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_convergence(values: np.ndarray, failed: np.ndarray, path: str | Path, title: str = "") -> None:
    """J per iteration (failed evaluations marked, at their penalty) and the best completed J so far."""
    fig, ax = plt.subplots(figsize=(9, 4.5))
    index = np.arange(len(values))
    ax.plot(index[~failed], values[~failed], ".", color="tab:blue", ms=4, label="completed")
    ax.plot(index[failed], values[failed], "x", color="tab:red", ms=4, label="failed (penalty)")
    best = [np.nan if b is None else b for b in best_so_far(values, ~failed)]
    ax.plot(index, best, "-", color="k", lw=1.5, label="best so far")
    ax.set_xlabel("iteration")
    ax.set_ylabel("J")
    ax.set_title(title, parse_math=False)  # a name's '$...$' is text, not mathtext
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_band(curves: list[list[float | None]], band: dict[str, list], labels: list[str], path: str | Path,
              title: str = "") -> None:
    """Best completed J so far of each job (thin lines), their median (thick) and interquartile band (shaded)."""
    fig, ax = plt.subplots(figsize=(9, 4.5))
    for curve, label in zip(curves, labels, strict=True):
        values = np.array([np.nan if v is None else v for v in curve], dtype=float)
        ax.plot(np.arange(len(values)), values, "-", lw=1.0, alpha=0.7, drawstyle="steps-post", label=label)
    ax.fill_between(band["iterations"], band["q25"], band["q75"], color="tab:blue", alpha=0.25, step="post",
                    label="25-75 % of seeds")
    ax.plot(band["iterations"], band["median"], "-", color="k", lw=2, drawstyle="steps-post", label="median")
    ax.set_xlabel("iteration")
    ax.set_ylabel("best J so far (completed)")
    ax.set_title(title, parse_math=False)  # a name's '$...$' is text, not mathtext
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_heatmap(table, path: str | Path, title: str = "") -> None:
    """A robustness study's J over its grid (a :class:`driftlab.core.study.GridTable`): completed cells coloured
    by J, failed cells light red and labelled with how they failed, pending cells blank."""
    values = np.array(table.J, dtype=float)
    failed = np.array([[s not in (EpisodeStatus.COMPLETED, "pending") for s in row] for row in table.status])
    fig, ax = plt.subplots(figsize=(max(5.0, 1.1 * values.shape[1] + 3), max(3.5, 0.6 * values.shape[0] + 2)))
    shown = np.where(failed, np.nan, values)
    finite = shown[np.isfinite(shown)]
    image = ax.imshow(shown, cmap="viridis_r", aspect="auto",
                      vmin=finite.min() if finite.size else None, vmax=finite.max() if finite.size else None)
    ax.imshow(np.where(failed, 1.0, np.nan), cmap=ListedColormap(["#f4c7c3"]), aspect="auto")
    for (r, c), bad in np.ndenumerate(failed):
        text = table.status[r][c] if bad else ("" if np.isnan(values[r, c]) else f"{values[r, c]:.2f}")
        ax.text(c, r, text, ha="center", va="center", fontsize=8, color="tab:red" if bad else "w")
    ax.set_yticks(range(len(table.row_values)), [str(v) for v in table.row_values])
    ax.set_ylabel(table.row_key)
    ax.set_xticks(range(len(table.column_labels)), table.column_labels, rotation=30, ha="right", fontsize=8)
    ax.set_xlabel(table.column_key)
    fig.colorbar(image, ax=ax, label="J (completed cells; lower is better)")
    ax.set_title(title, fontsize=9, parse_math=False)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
