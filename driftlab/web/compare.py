"""A tab's compare mode: choose jobs (by id) or a study; their convergence (best J so far) overlaid, with the
median and the 25-75 % band of a seeds study shaded; their best episodes played together as ghost cars; and a
robustness study's heatmap (completed or failed, and J, over its grid).

It draws what storage holds (read through callbacks), and is refreshed by the view app's poller while a
comparison is shown.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from typing import Any

import numpy as np
import viser

from driftlab.core.study import grid_table
from driftlab.markup import plain
from driftlab.web.heatmap import heatmap_html
from driftlab.web.player import CAR_COLOR, GHOST_COLOR, MORE_GHOST_COLORS
from driftlab.web.plots import padded_range, series

NO_STUDY = "(no study: compare the job ids above)"
CAR_COLORS = (CAR_COLOR, GHOST_COLOR, *MORE_GHOST_COLORS)  # the car, then the ghosts, in order
COLOR_NAMES = ("red", "blue", "green", "purple", "orange", "teal", "pink", "grey", "brown")  # of CAR_COLORS
MAX_JOBS = len(CAR_COLORS)
BAND_FILL = "rgba(42, 111, 219, 0.18)"


def _hex(rgb: tuple[int, int, int]) -> str:
    return "#{:02x}{:02x}{:02x}".format(*rgb)


def _same(a: tuple[np.ndarray, ...], b: tuple[np.ndarray, ...]) -> bool:
    return len(a) == len(b) and all(np.array_equal(x, y, equal_nan=True) for x, y in zip(a, b, strict=True))


def study_label(study_id: int, name: str, kind: str, status: str) -> str:
    return f"{study_id} · {name} · {kind} · {status}"


def parse_job_ids(text: str) -> list[int]:
    """'1, 2,3' -> [1, 2, 3] (ValueError naming the problem)."""
    try:
        ids = [int(part) for part in text.replace(" ", "").split(",") if part]
    except ValueError:
        raise ValueError(f"job ids must be comma-separated integers, got {text!r}") from None
    if not 1 <= len(ids) <= MAX_JOBS:
        raise ValueError(f"compare 1 to {MAX_JOBS} jobs, got {len(ids)}")
    return ids


def _shown(value: Any) -> str:
    """A setting's value in the diff table: numbers to 4 significant digits (the API has them in full)."""
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, list):
        return "[" + ", ".join(_shown(v) for v in value) + "]"
    return "-" if value is None else str(value)


def _time(seconds: float | None) -> str:
    return "-" if seconds is None else f"{seconds:.2f}"


def config_diff_markdown(diff: dict[str, Any]) -> str:
    """The settings that differ between the compared jobs, one column per job (GET /api/compare/config)."""
    jobs = diff["jobs"]
    if len(jobs) < 2:
        return ""
    if not diff["differences"]:
        return "**Config diff**: the jobs' settings are the same (they differ in seed only, if at all)."
    header = "| setting | " + " | ".join(f"{plain(j['name'])} (id {j['id']})" for j in jobs) + " |"
    rows = [f"| {plain(d['key'])} | " + " | ".join(plain(_shown(v)) for v in d["values"]) + " |"
            for d in diff["differences"]]
    return "\n".join(["**Config diff** (settings that differ)", "", header, "|---" * (len(jobs) + 1) + "|", *rows])


def convergence_data(jobs: list[dict[str, Any]], band: dict[str, list] | None
                     ) -> tuple[tuple[np.ndarray, ...], tuple[dict[str, Any], ...], tuple[dict[str, Any], ...]]:
    """uPlot data, series and bands: x, each job's best J so far, and with a band its median, q75 and q25."""
    length = max([len(j["convergence"]["best_so_far"]) for j in jobs] + [2])
    x = np.arange(length, dtype=float)
    data = [x]
    styles = [series("evaluation", "#888")]
    for n, job in enumerate(jobs):
        curve = np.full(length, np.nan)
        values = job["convergence"]["best_so_far"]
        curve[: len(values)] = [np.nan if v is None else v for v in values]
        data.append(curve)
        styles.append(series(f"{job['name']} (id {job['id']})", _hex(CAR_COLORS[n % len(CAR_COLORS)])))
    if not jobs:  # uPlot needs a y series
        data.append(np.full(length, np.nan))
        styles.append(series("no jobs chosen", "#888"))
    bands: tuple[dict[str, Any], ...] = ()
    if band is not None and band["iterations"]:
        columns = {name: np.full(length, np.nan) for name in ("median", "q75", "q25")}
        for k, i in enumerate(band["iterations"]):
            for name, column in columns.items():
                column[i] = band[name][k]
        first = len(data)
        data += [columns["median"], columns["q75"], columns["q25"]]
        styles += [series("median", "#111", width=3.0), series("q75", "rgba(42,111,219,0.6)", width=1.0),
                   series("q25", "rgba(42,111,219,0.6)", width=1.0)]
        bands = ({"series": (first + 1, first + 2), "fill": BAND_FILL},)
    return tuple(data), tuple(styles), bands


class ComparePanel:
    """The compare folder of one tab.

    Args:
        read_studies: (id, name, kind, status) of every study.
        read_study: a study's summary (as GET /api/studies/{id}).
        read_compare: jobs' summaries (as GET /api/compare).
        read_config_diff: the settings that differ between jobs (as GET /api/compare/config).
        play_together: plays the given evaluations (by id) together, with a caption line each.
        lock: the tab's lock.
    """

    def __init__(self, gui: viser.GuiApi, *, read_studies: Callable[[], list[tuple[int, str, str, str]]],
                 read_study: Callable[[int], dict[str, Any]],
                 read_compare: Callable[[list[int]], list[dict[str, Any]]],
                 read_config_diff: Callable[[list[int]], dict[str, Any]],
                 play_together: Callable[[list[int], list[str]], None], lock: threading.RLock) -> None:
        self.gui = gui
        self.read_studies, self.read_study, self.read_compare = read_studies, read_study, read_compare
        self.read_config_diff = read_config_diff
        self.diff: dict[str, Any] = {"jobs": [], "differences": []}
        self.play_together = play_together
        self.lock = lock
        self.active = False
        self.jobs: list[dict[str, Any]] = []
        self.study: dict[str, Any] | None = None
        self.folder = gui.add_folder("Compare", expand_by_default=False)
        with self.folder:
            gui.add_markdown("Choose jobs by id, or a study: their best J so far overlaid (a seeds study: median "
                             "and 25-75 % band shaded), their best episodes played together as ghost cars, or a "
                             "robustness study's heatmap.")
            self.gui_jobs = gui.add_text("Job ids", "", hint="comma-separated, e.g. 1,2,3")
            self.gui_study = gui.add_dropdown("Study", (NO_STUDY,))
            self.gui_compare = gui.add_button("Show comparison", icon=viser.Icon.CHART_LINE)
            self.text = gui.add_markdown("")
            self.plot = self._add_plot(*convergence_data([], None))
            self._plot_layout: tuple = ()
            self.gui_play = gui.add_button("Play best episodes together", icon=viser.Icon.CAR, visible=False)
            self.heatmap = gui.add_html("", visible=False)
            self.config_diff = gui.add_markdown("")
        self.gui_compare.on_click(lambda _: self.compare())
        self.gui_play.on_click(lambda _: self.play())

    def _add_plot(self, data, styles, bands, order: float | None = None) -> viser.GuiUplotHandle:
        return self.gui.add_uplot(data, styles, bands=bands or None, title="Compare: best J so far (completed)",
                                  aspect=1.6, scales={"x": {"time": False}}, order=order,
                                  axes=({"label": "evaluation"}, {"label": "best J so far"}))

    def set_study_options(self, studies: list[tuple[int, str, str, str]]) -> None:
        options = (NO_STUDY, *(study_label(*s) for s in studies))
        current = self.gui_study.value
        self.gui_study.options = options
        chosen = next((o for o in options if o.split(" ·")[0] == current.split(" ·")[0]), NO_STUDY)
        if self.gui_study.value != chosen:
            self.gui_study.value = chosen

    def compare(self) -> None:
        """Reads what was chosen and shows it (the study if one is chosen, else the job ids)."""
        with self.lock:
            try:
                self._read_selection()
            except (ValueError, LookupError) as exc:
                self.text.content = f"**error**: {plain(exc)}"
                return
            self.active = True
            self._show()

    def refresh(self) -> None:
        """The poller's call while a comparison is shown: read it again, draw it again."""
        with self.lock:
            if not self.active:
                return
            try:
                self._read_selection()
            except (ValueError, LookupError):
                return
            self._show()

    def _read_selection(self) -> None:
        label = self.gui_study.value
        if label != NO_STUDY:
            self.study = self.read_study(int(label.split(" ·")[0]))
            ids = self.study["job_ids"][:MAX_JOBS]
        else:
            self.study = None
            ids = parse_job_ids(self.gui_jobs.value)
        self.jobs = self.read_compare(ids) if ids else []
        self.diff = self.read_config_diff(ids) if len(ids) > 1 else {"jobs": [], "differences": []}

    def _show(self) -> None:
        study = self.study
        if study is not None and study["kind"] == "robustness":
            table = grid_table(study["grid"], study["cells"])
            self.heatmap.content = heatmap_html(table, f"{study['name']}: theta {study['theta']}")
            self.heatmap.visible = True
            self.plot.visible = False
            self.gui_play.visible = False
            self.text.content = (f"**{plain(study['name'])}** (robustness, {study['status']}): {study['n_done']} of "
                                 f"{study['n_cells']} cells run")
            self.config_diff.content = ""
            return
        if self.heatmap.visible:
            self.heatmap.visible = False
        self._replace_plot(*convergence_data(self.jobs, study["band"] if study is not None else None))
        self.gui_play.visible = bool(self.jobs)
        self.text.content = self._jobs_table(study)
        diff = config_diff_markdown(self.diff)
        if self.config_diff.content != diff:
            self.config_diff.content = diff

    def _replace_plot(self, data, styles, bands) -> None:
        """New data for the plot; a new uPlot in the old one's place when the series change (other jobs)."""
        layout = (tuple(s["label"] for s in styles), bool(bands))
        if not self.plot.visible:
            self.plot.visible = True
        if layout == self._plot_layout:
            if _same(data, self.plot.data):  # nothing new: no message (the client redraws the plot on one)
                return
            self.plot.data = data
        else:
            order = self.plot.order
            self.plot.remove()
            with self.folder:
                self.plot = self._add_plot(data, styles, bands, order=order)
            self._plot_layout = layout
        values = np.concatenate([d for d in data[1:]]) if len(data) > 1 else np.zeros(0)
        self.plot.scales = {"x": {"time": False, "range": (0.0, float(max(len(data[0]) - 1, 1)))},
                            "y": {"range": padded_range(values)}}

    def _jobs_table(self, study: dict[str, Any] | None) -> str:
        lines = []
        if study is not None:
            final = study.get("final_best_J") or []
            spread = (f"; final best J from {min(final):.4g} to {max(final):.4g}, median {np.median(final):.4g}"
                      if final else "")
            lines.append(f"**{plain(study['name'])}** (seeds, {study['status']}){spread}")
        lines += ["| colour | job | seed | done | best J |", "|---|---|---|---|---|"]
        for n, job in enumerate(self.jobs):
            best = job["best"]
            value = "-" if best is None or not math.isfinite(best["J"]) else f"{best['J']:.4g} ({best['status']})"
            lines.append(f"| {COLOR_NAMES[n % len(COLOR_NAMES)]} | {plain(job['name'])} (id {job['id']}) | "
                         f"{job['seed']} | {job['n_done']} / {job['iterations']} | {value} |")
        return "\n".join(lines + self._flicks_table())

    def _flicks_table(self) -> list[str]:
        """Each job's best episode through its flicks: sign change and settle times [s], speed loss [m/s], mean
        |e| [m] (metrics.phases)."""
        rows = []
        for n, job in enumerate(self.jobs):
            flicks = [p for p in job.get("best_phases", []) if "flip_s" in p]
            # "\\|": a bare | inside a cell ends it (the mean |e| was cut off); the speed loss as the dashboard
            # shows it (metrics.phases' speed_loss_mps: positive, the speed lost)
            cells = "; ".join(f"{_time(p['flip_s'])} / {_time(p['settle_s'])} s, loses {p['speed_loss_mps']:.2f} "
                              f"m/s, mean \\|e\\| {p['mean_abs_e_m']:.2f} m" for p in flicks)
            rows.append(f"| {COLOR_NAMES[n % len(COLOR_NAMES)]} | {cells or '-'} |")
        return ["", "| colour | flicks of the best episode: sign change / settled, speed loss, mean \\|e\\| |",
                "|---|---|", *rows]

    def play(self) -> None:
        with self.lock:
            chosen = [(n, j) for n, j in enumerate(self.jobs) if j["best"] is not None]
            if not chosen:
                self.text.content = "None of these jobs has an evaluation yet."
                return
            # Cars in the order played: the first is the red car, the next the ghosts (the plot's colours when
            # every job has an evaluation).
            captions = [f"{COLOR_NAMES[k]}{' car' if k == 0 else ' ghost'}: {plain(j['name'])}, best J "
                        f"{j['best']['J']:.4g}, evaluation id {j['best']['id']}"
                        for k, (_, j) in enumerate(chosen)]
            self.play_together([j["best"]["id"] for _, j in chosen], captions)
