"""uPlot helpers shared by the tab's panels: series styles and y ranges that keep several ticks."""

from __future__ import annotations

from typing import Any

import numpy as np


def series(label: str, color: str, *, points: bool = False, width: float = 1.5) -> dict[str, Any]:
    if points:
        return {"label": label, "stroke": color, "width": 0, "points": {"show": True, "size": 6, "fill": color}}
    return {"label": label, "stroke": color, "width": width, "points": {"show": False}}


def padded_range(values: np.ndarray, min_span: float = 0.0) -> tuple[float, float]:
    """A y range around the finite values, 8% padded and at least ``min_span`` wide (uPlot puts a single tick
    on a range much narrower than its tick spacing: the steering plot had one)."""
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return (-1.0, 1.0)
    lo, hi = float(finite.min()), float(finite.max())
    pad = max(0.08 * (hi - lo), 0.05, 0.5 * (min_span - (hi - lo)))
    return (lo - pad, hi + pad)
