"""The paper's figures (Fig. 4 and 5) from an episode trajectory; an edge module, outside core/."""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from driftlab.core.episode import EpisodeResult  # noqa: E402
from driftlab.core.track import FigureEight  # noqa: E402


def _draw_track(ax, track: FigureEight) -> None:
    angles = np.linspace(0.0, 2.0 * math.pi, 361)
    for circle, colour in ((track.left, "tab:blue"), (track.right, "tab:green")):
        ax.plot(circle.center_x_m + circle.radius_m * np.cos(angles),
                circle.center_y_m + circle.radius_m * np.sin(angles), "--", color=colour, lw=1, alpha=0.6)
    ax.plot([0.0], [0.0], "ko", ms=4, label="P0")


def plot_episode(result: EpisodeResult, track: FigureEight, path: str | Path, title: str = "") -> None:
    """x-y path with both circles and trigger points, and V, beta, r, delta against references."""
    fig = plt.figure(figsize=(13, 8))
    grid = fig.add_gridspec(4, 2, width_ratios=[1.1, 1.4])
    ax_xy = fig.add_subplot(grid[:, 0])
    _draw_track(ax_xy, track)
    ax_xy.plot(result.column("x_m"), result.column("y_m"), color="tab:red", lw=1.5, label="path")
    for i, trig in enumerate(result.trigger_points):
        ax_xy.plot(trig["x_m"], trig["y_m"], "o", color="tab:orange", ms=8, label="trigger" if i == 0 else None)
    ax_xy.set_aspect("equal")
    ax_xy.set_xlabel("x [m]")
    ax_xy.set_ylabel("y [m]")
    ax_xy.legend(loc="upper right", fontsize=8)
    # Over the whole figure: a long title (theta at full precision) above the narrow x-y axes ran off its left.
    fig.suptitle(title or f"{result.status}, J = {result.J:.3f}", fontsize=9)
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
    best = np.minimum.accumulate(np.where(failed, np.inf, values))
    ax.plot(index, np.where(np.isfinite(best), best, np.nan), "-", color="k", lw=1.5, label="best so far")
    ax.set_xlabel("iteration")
    ax.set_ylabel("J")
    ax.set_title(title)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
