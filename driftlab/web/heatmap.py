"""A robustness study's heatmap as an HTML table for the view's panel: completed cells coloured by J (the
lowest, best, yellow; the highest purple), failed cells light red with how they failed (or `not_drivable`:
not run), pending cells grey."""

from __future__ import annotations

import html
import math

import numpy as np

from driftlab.core.statuses import EpisodeStatus
from driftlab.core.study import GridTable

# viridis at 0, 0.25, 0.5, 0.75, 1 (matplotlib's), reversed below so that a low J is bright.
_VIRIDIS = np.array([(68, 1, 84), (59, 82, 139), (33, 145, 140), (94, 201, 98), (253, 231, 37)], dtype=float)
FAILED_COLOR = "#f4c7c3"
PENDING_COLOR = "#e9ecef"


def j_color(value: float, lo: float, hi: float) -> str:
    """The cell colour of J = value on the scale [lo, hi] (lower is better: yellow)."""
    x = 0.5 if hi <= lo else 1.0 - (value - lo) / (hi - lo)
    position = float(np.clip(x, 0.0, 1.0)) * (len(_VIRIDIS) - 1)
    i = min(int(position), len(_VIRIDIS) - 2)
    rgb = _VIRIDIS[i] + (position - i) * (_VIRIDIS[i + 1] - _VIRIDIS[i])
    return "#{:02x}{:02x}{:02x}".format(*(int(round(c)) for c in rgb))


def _cell(status: str, value: float, lo: float, hi: float) -> str:
    if status == "pending":
        return f'<td style="background:{PENDING_COLOR};color:#888">…</td>'
    if status != EpisodeStatus.COMPLETED:
        title = "" if math.isnan(value) else f' title="J {value:.4g}"'
        return f'<td style="background:{FAILED_COLOR};color:#a61e1e"{title}>{html.escape(status)}</td>'
    text_color = "#000" if value <= 0.5 * (lo + hi) else "#fff"
    return f'<td style="background:{j_color(value, lo, hi)};color:{text_color}">{value:.4g}</td>'


def heatmap_html(table: GridTable, title: str = "") -> str:
    completed = [v for row, srow in zip(table.J, table.status, strict=True)
                 for v, s in zip(row, srow, strict=True) if s == EpisodeStatus.COMPLETED]
    lo, hi = (min(completed), max(completed)) if completed else (0.0, 1.0)
    style = "border-collapse:collapse;font-size:11px;text-align:center"
    cell_style = "td,th{border:1px solid #fff;padding:4px 6px}"
    head = "".join(f"<th>{html.escape(label)}</th>" for label in table.column_labels)
    rows = []
    for value, j_row, s_row in zip(table.row_values, table.J, table.status, strict=True):
        cells = "".join(_cell(s, v, lo, hi) for v, s in zip(j_row, s_row, strict=True))
        rows.append(f"<tr><th>{html.escape(str(value))}</th>{cells}</tr>")
    n_failed = sum(s not in (EpisodeStatus.COMPLETED, "pending") for row in table.status for s in row)
    legend = (f"J of completed cells from {lo:.4g} (yellow, best) to {hi:.4g} (purple); {n_failed} failed (red)"
              if completed else f"no completed cell yet; {n_failed} failed (red)")
    columns = (f'<tr><th></th><th colspan="{len(table.column_labels)}">{html.escape(table.column_key)} →</th></tr>'
               if table.column_key else "")
    return (f'<div style="font-size:12px"><style>{cell_style}</style><b>{html.escape(title)}</b>'
            f'<table style="{style}">{columns}<tr><th>{html.escape(table.row_key)} ↓</th>{head}</tr>{"".join(rows)}'
            f'</table><div style="font-size:11px">{html.escape(legend)}</div></div>')
