"""The standalone HTML replay's side panel: what the episode is (evaluation, J, theta, plant) and its state plots
(V, beta, r and delta against their references), beside viser's 3D player in the same page.

A recording holds the scene only (no GUI panel), so the panel is plain HTML with inline SVG added to the page
viser writes; it needs no server and no script.
"""

from __future__ import annotations

import html
import re

import numpy as np

from driftlab.web.frames import EpisodeFrames
from driftlab.web.plots import padded_range

PANEL_WIDTH_PX = 440
_PLOT_W, _PLOT_H = 400, 130
_MARGIN = {"l": 48, "r": 8, "t": 18, "b": 22}
STATE_PLOTS = (("V_mps", "V_ref_mps", "V [m/s]"), ("beta_rad", "beta_ref_rad", "beta [rad]"),
               ("r_radps", "r_ref_radps", "r [rad/s]"), ("delta_rad", "delta_ref_rad", "delta [rad]"))


def _ticks(lo: float, hi: float, count: int = 4) -> list[float]:
    raw = (hi - lo) / count
    magnitude = 10 ** np.floor(np.log10(raw)) if raw > 0 else 1.0
    step = next(m * magnitude for m in (1, 2, 2.5, 5, 10) if m * magnitude >= raw)
    return [float(v) for v in np.arange(np.ceil(lo / step) * step, hi + 1e-9 * step, step)]


def _polyline(x: np.ndarray, y: np.ndarray, sx, sy, color: str) -> str:
    finite = np.isfinite(y)
    points = " ".join(f"{sx(a):.1f},{sy(b):.1f}" for a, b in zip(x[finite], y[finite], strict=True))
    return f'<polyline points="{points}" fill="none" stroke="{color}" stroke-width="1.4"/>'


def state_plot_svg(t_s: np.ndarray, actual: np.ndarray, reference: np.ndarray, label: str) -> str:
    """One state against its reference over the episode, as an inline SVG with ticked axes."""
    x_lo, x_hi = 0.0, max(float(t_s[-1]), 0.1) if len(t_s) else 0.1
    y_lo, y_hi = padded_range(np.concatenate([actual, reference]), min_span=0.4)
    m = _MARGIN
    def sx(v): return m["l"] + (v - x_lo) / (x_hi - x_lo) * (_PLOT_W - m["l"] - m["r"])  # noqa: E704
    def sy(v): return _PLOT_H - m["b"] - (v - y_lo) / (y_hi - y_lo) * (_PLOT_H - m["t"] - m["b"])  # noqa: E704
    parts = [f'<svg width="{_PLOT_W}" height="{_PLOT_H}" viewBox="0 0 {_PLOT_W} {_PLOT_H}">',
             f'<text x="{m["l"]}" y="12" class="t">{html.escape(label)} <tspan fill="#2a6fdb">actual</tspan> '
             f'<tspan fill="#e8590c">reference</tspan></text>',
             f'<rect x="{m["l"]}" y="{m["t"]}" width="{_PLOT_W - m["l"] - m["r"]}" '
             f'height="{_PLOT_H - m["t"] - m["b"]}" fill="#fff" stroke="#bbb"/>']
    for v in _ticks(x_lo, x_hi, 6):
        parts.append(f'<text x="{sx(v):.1f}" y="{_PLOT_H - 6}" text-anchor="middle">{v:.4g}</text>')
    for v in _ticks(y_lo, y_hi):
        parts.append(f'<text x="{m["l"] - 4}" y="{sy(v) + 4:.1f}" text-anchor="end">{v:.4g}</text>')
    parts.append(_polyline(t_s, reference, sx, sy, "#e8590c"))
    parts.append(_polyline(t_s, actual, sx, sy, "#2a6fdb"))
    parts.append("</svg>")
    return "".join(parts)


def replay_panel_html(frames: EpisodeFrames, ghost: EpisodeFrames | None = None) -> str:
    """The panel: the evaluation, its status and J, theta and plant settings (4 significant digits; the
    trajectory download has them in full), and the state plots; with a ghost, which episode it drives."""
    theta = "".join(f"<tr><td>{html.escape(k)}</td><td>{v:.4g}</td></tr>" for k, v in frames.theta.items())
    plant = "".join(f"<tr><td>{html.escape(k)}</td><td>{v:.4g}</td></tr>" for k, v in frames.plant.items())
    plots = "".join(state_plot_svg(frames.column("t_s"), frames.column(a), frames.column(r), label)
                    for a, r, label in STATE_PLOTS) if frames.n_frames else ""
    triggers = ", ".join(f"{p['t_s']:.2f} s" for p in frames.trigger_points) or "none"
    return (f'<aside id="driftlab-panel"><h1>{html.escape(frames.name())}</h1>'
            f'<p class="j">{html.escape(frames.status)} · {html.escape(frames.j_text())}</p>'
            + (f'<p>plant: {html.escape(frames.car)}</p>' if frames.car else "")
            + (f'<p>beside it, the translucent car: {html.escape(ghost.name())} · {html.escape(ghost.status)} · '
               f'{html.escape(ghost.j_text())}</p>' if ghost is not None else "")
            + f'<p>triggers at {triggers} · duration {frames.duration_s:.4g} s</p>'
            f'<table><tr><th colspan="2">theta</th></tr>{theta}'
            + (f'<tr><th colspan="2">plant (changed)</th></tr>{plant}' if plant else "")
            + f"</table>{plots}</aside>")


_STYLE = (f"<style>#root{{position:fixed;left:0;top:0;bottom:0;right:{PANEL_WIDTH_PX}px;width:auto!important}}"
          f"#driftlab-panel{{position:fixed;right:0;top:0;bottom:0;width:{PANEL_WIDTH_PX - 24}px;overflow:auto;"
          "padding:8px 12px;background:#fafafa;border-left:1px solid #ddd;font:13px/1.35 system-ui,sans-serif;"
          "color:#222}#driftlab-panel h1{font-size:15px;margin:2px 0}#driftlab-panel .j{font-weight:600}"
          "#driftlab-panel table{border-collapse:collapse;margin:4px 0}#driftlab-panel td,#driftlab-panel th{"
          "padding:1px 8px 1px 0;text-align:left}#driftlab-panel svg text{font-size:10px;fill:#444}"
          "#driftlab-panel svg .t{font-size:11px;fill:#222}</style>")


def with_panel(viser_html: str, frames: EpisodeFrames, ghost: EpisodeFrames | None = None) -> str:
    """viser's standalone page with the panel on the right and the 3D player beside it."""
    head_end = viser_html.index("</head>")
    title = f"<title>{html.escape(frames.name())}, J {frames.J:.4g} · DriftLab replay</title>"
    page = re.sub(r"<title>.*?</title>", "", viser_html[:head_end], flags=re.S) + title + _STYLE + viser_html[head_end:]
    body = page.index("<body>") + len("<body>")
    return page[:body] + replay_panel_html(frames, ghost) + page[body:]
