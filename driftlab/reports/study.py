"""`driftlab report --study NAME`: a study's figures and table (a seeds study's band, a robustness study's
heatmap), from what is stored; nothing is re-run."""

from __future__ import annotations

import statistics
from pathlib import Path

from driftlab.core.statuses import EpisodeStatus, StudyKind
from driftlab.core.study import grid_table
from driftlab.db import storage, studies
from driftlab.markup import plain
from driftlab.reports.plotting import plot_band, plot_heatmap
from driftlab.services import studies as study_views


def _seeds_lines(summary: dict, session, out: Path) -> list[str]:
    jobs = [study_views.job_summary(session, storage.get_job(session, job_id=i)) for i in summary["job_ids"]]
    curves = [j["convergence"]["best_so_far"] for j in jobs]
    band = summary["band"]
    plot_band(curves, band, [f"seed {j['seed']}" for j in jobs], out / "band.png",
              title=f"{summary['name']}: best J so far over {len(jobs)} seeds")
    lines = ["| job | seed | status | evaluations | best J |", "|---|---|---|---|---|"]
    for j in jobs:
        best = "-" if j["best"] is None else f"{j['best']['J']:.4f} ({j['best']['status']})"
        lines.append(f"| {plain(j['name'])} | {j['seed']} | {j['status']} | {j['n_done']} | {best} |")
    final = summary["final_best_J"]
    if final:
        lines += ["", f"Final best J over seeds: median {statistics.median(final):.4f}, "
                      f"min {min(final):.4f}, max {max(final):.4f} (spread {max(final) - min(final):.4f})."]
    if band["iterations"]:
        lines += ["", "| iteration | median | q25 | q75 | seeds |", "|---|---|---|---|---|"]
        step = max(1, len(band["iterations"]) // 10)
        for k in sorted(set(range(0, len(band["iterations"]), step)) | {len(band["iterations"]) - 1}):
            lines.append(f"| {band['iterations'][k]} | {band['median'][k]:.4f} | {band['q25'][k]:.4f} | "
                         f"{band['q75'][k]:.4f} | {band['n'][k]} |")
    return lines + ["", "![band](band.png)", ""]


def _robustness_lines(summary: dict, out: Path) -> list[str]:
    table = grid_table(summary["grid"], summary["cells"])
    plot_heatmap(table, out / "heatmap.png", title=f"{summary['name']}: theta {summary['theta']}")
    done = [c for c in summary["cells"] if c["status"] != studies.PENDING]
    completed = [c for c in done if c["status"] == EpisodeStatus.COMPLETED]
    lines = [f"Theta {summary['theta']} on {summary['n_cells']} cells ({len(done)} run, {len(completed)} "
             "completed on every seed).", "", "| settings | status | J | seeds completed |", "|---|---|---|---|"]
    for c in summary["cells"]:
        value = "-" if c["J"] is None else f"{c['J']:.4f}"
        seeds = "-" if c["n_completed"] is None else f"{c['n_completed']}/{len(c['seeds'])}"
        lines.append(f"| {c['settings']} | {c['status']} | {value} | {seeds} |")
    return lines + ["", "![heatmap](heatmap.png)", ""]


def write_study_report(*, db_url: str, name: str, out_dir: str) -> Path:
    factory = storage.open_database(db_url)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    with storage.snapshot(factory) as session:
        summary = study_views.study_summary(session, studies.get_study_by_name(session, name=name))
        header = [f"# DriftLab study report: {plain(name)}", "", f"A {summary['kind']} study, {summary['status']}. "
                  "Lower J is better.", ""]
        if summary["kind"] == StudyKind.SEEDS:
            lines = _seeds_lines(summary, session, out)
        else:
            lines = _robustness_lines(summary, out)
    path = out / "report.md"
    path.write_text("\n".join(header + lines))
    return path
