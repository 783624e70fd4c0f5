"""`driftlab report`: the paper's results for a finished tuning job (markdown, figures, baselines)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from driftlab.core.config import PAPER_THETA, Theta
from driftlab.core.equilibrium import drift_equilibrium
from driftlab.core.robust import PHASE_GROUPS, aggregate, rescore_seeds, summarize
from driftlab.core.statuses import EpisodeStatus
from driftlab.core.track import FigureEight
from driftlab.core.tuning import TuningSpec
from driftlab.core.vehicle import pack_params
from driftlab.db import storage
from driftlab.markup import plain
from driftlab.reports.plotting import plot_convergence, plot_episode
from driftlab.services import read_model
from driftlab.worker.executors import open_executor
from driftlab.worker.scoring import score_thetas

# The paper's Table I (left-hand drift at R = 44 m, beta = -0.4; docs/reference.md, The car).
PAPER_TABLE_I = {"V": 19.1, "beta": -0.4, "r": 0.434, "delta": -0.270, "Fxr": 4324.0}


def write_report(*, db_url: str, name: str, out_dir: str, baseline_samples: int | None = None,
                 rescore_samples: int = 20, dask_address: str | None = None) -> Path:
    factory = storage.open_database(db_url)
    with storage.snapshot(factory) as session:
        job = storage.get_job_by_name(session, name=name)
        spec = TuningSpec.from_dict(job.spec)
        evals = storage.evaluations(session, job_id=job.id)
        best = storage.best_evaluation(session, job_id=job.id)
    if best is None:
        raise storage.NotFound(f"job {name!r} has no evaluations yet")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    config = spec.config
    track = FigureEight(config.scenario.left_radius_m, config.scenario.right_radius_m,
                        config.scenario.laps)
    # A job keeps its best's trajectory (driftlab.db.storage.add_evaluation); the plot is that stored episode.
    shown = read_model.stored_episode(factory, best.id)
    plot_episode(shown, track, str(out / "best_episode.png"),
                 title=f"{name}: best, evaluation id {best.id} (index {best.index}), {best.status}\n"
                       f"J = {best.J:.3f} over its seeds; shown: seed {shown.seed}, J = {shown.episode_J:.3f}",
                 lap_errors_m=shown.metrics.get("lap_mean_abs_e_m", ()))
    values = np.array([e.J for e in evals])
    failed = np.array([not e.completed for e in evals])
    plot_convergence(values, failed, str(out / "convergence.png"), title=f"{name}: J per iteration")

    n_random = baseline_samples or len(evals)
    rng = np.random.default_rng(spec.seed + 12345)
    samples = [{k: float(rng.uniform(lo, hi)) for k, (lo, hi) in spec.bounds.items()} for _ in range(n_random)]
    config_doc = spec.to_dict()["config"]
    executor, _ = open_executor(None if dask_address else 2, dask_address)
    try:
        # The random baseline is scored as tuning scored (the job's seeds, same aggregate); then every theta
        # of the table is rescored under fresh seeds.
        random_scores = [aggregate(r) for r in score_thetas(executor, samples, config_doc, spec.episode_seeds)]
        ranked = sorted(range(n_random),
                        key=lambda i: (random_scores[i].status != EpisodeStatus.COMPLETED, random_scores[i].J))
        random_best = samples[ranked[0]]
        table = [("learned (best)", dict(best.theta), best.status, best.J),
                 ("untuned", Theta().as_dict(), None, None), ("paper's", PAPER_THETA.as_dict(), None, None),
                 (f"best of {n_random} random", random_best, random_scores[ranked[0]].status,
                  random_scores[ranked[0]].J)]
        rescored = score_thetas(executor, [row[1] for row in table], config_doc, rescore_seeds(rescore_samples))
    finally:
        executor.shutdown()

    eq = drift_equilibrium(config.scenario.left_radius_m, -abs(config.scenario.sideslip_rad),
                           pack_params(config.vehicle)).as_dict()
    lines = [f"# DriftLab report: {plain(name)}", "",
             f"{len(evals)} evaluations ({int((~failed).sum())} completed), {spec.robust_samples} seeded episodes "
             f"per evaluation, seed points {spec.seed_points}, active set {spec.active_set}, bounds {spec.bounds}. "
             "Lower J is better.", "",
             "## Drift equilibria (R = 44 m) and learned parameters", "",
             "| | V (m/s) | beta (rad) | r (rad/s) | delta (rad) | Fxr (N) |", "|---|---|---|---|---|---|",
             "| paper Table I | {V:.3f} | {beta:.4f} | {r:.4f} | {delta:.4f} | {Fxr:.0f} |".format(**PAPER_TABLE_I),
             "| DriftLab model | {V:.3f} | {beta:.4f} | {r:.4f} | {delta:.4f} | {Fxr:.0f} |".format(**eq), "",
             f"Theta at full precision. 'Tuning J': on the job's {spec.robust_samples} seeds (mean J over them, "
             f"an evaluation completes only if all do). 'Rescore': {rescore_samples} fresh seeds never used in "
             "tuning (J mean over all episodes, failures at their penalty).", "",
             "Rescore's path and sideslip errors over its completed episodes: of the whole episode, of the sustained "
             "drifts and of the flicks (each episode's mean over its steps in them, then the mean over the episodes; "
             "the largest; the RMS).", "",
             "| theta | c_lr | c_rl | dV (m/s) | k (rad/m) | model mu x | model C x | tuning status | tuning J | "
             "rescore completed | rescore J mean | rescore J worst | mean \\|e\\| all / drift / flick (m) | "
             "max \\|e\\| drift / flick (m) | RMS beta error drift / flick (rad) |", "|---" * 15 + "|"]
    summaries = [summarize(results) for results in rescored]
    for (label, theta, status, value), summary in zip(table, summaries, strict=True):
        tuning = (status or "-", "-" if value is None else f"{value:.3f}")
        theta = Theta.filled(theta)
        lines.append(f"| {label} | {theta['c_lr']!r} | {theta['c_rl']!r} | {theta['dV']!r} | {theta['k']!r} | "
                     f"{theta['model_mu_scale']!r} | {theta['model_c_scale']!r} | {tuning[0]} | {tuning[1]} | "
                     f"{completed_cell(summary)} | "
                     f"{summary['J_mean']:.3f} | {summary['J_worst']:.3f} | {phase_cells(summary)} |")
    lines += _verdict(summaries[0], summaries[1], len(evals), spec.seed_points)
    lines += ["", f"## The drift and the flicks, phase by phase (best evaluation, seed {shown.seed})", "",
              *phase_table(shown.metrics.get("phases", []))]
    lines += ["", "![best episode](best_episode.png)", "", "![convergence](convergence.png)", ""]
    path = out / "report.md"
    path.write_text("\n".join(lines))
    return path


PHASE_NAMES = {"left_drift": "left drift", "inertia_left_to_right": "flick left -> right", "right_drift":
               "right drift", "inertia_right_to_left": "flick right -> left", "left_drift_final": "final left drift"}


def phase_table(phases: list[dict]) -> list[str]:
    """Markdown rows of an episode's phases (driftlab.core.metrics.phase_segments): each drift and each flick with
    its path error, sideslip error, countersteer share, and a flick's sign-change and settle times and speed loss."""
    lines = ["| phase | from-to (s) | mean / max \\|e\\| (m) | RMS beta error (rad) | countersteer | "
             "sign change (s) | settled (s) | speed loss (m/s) |", "|---" * 8 + "|"]
    for p in phases:
        share = p.get("countersteer_share")  # None: stored before it was measured
        flick = [_number(p.get("flip_s"), 2), _number(p.get("settle_s"), 2)] if "flip_s" in p else ["", ""]
        lines.append(f"| {PHASE_NAMES.get(p['phase'], p['phase'])} | {p['start_s']:.2f}-{p['end_s']:.2f} | "
                     f"{p['mean_abs_e_m']:.2f} / {p['max_abs_e_m']:.2f} | {_number(p.get('rms_beta_err_rad'), 3)} | "
                     f"{'-' if share is None else f'{100 * share:.0f}%'} | {flick[0]} | {flick[1]} | "
                     f"{p['speed_loss_mps']:.2f} |")
    return lines


def completed_cell(summary: dict) -> str:
    """Completed of all, and how many ended outside the plant's model (``invalid``: MB with a wheel pulling the road
    or two wheels of one side in the air), which are failures like the others but no fault of the controller."""
    invalid = summary.get("statuses", {}).get(EpisodeStatus.INVALID, 0)
    return f"{summary['completed']}/{summary['samples']}" + (f" ({invalid} invalid)" if invalid else "")


def phase_cells(summary: dict) -> str:
    """A rescore summary's (driftlab.core.robust.summarize) errors as three table cells: mean |e| of the whole
    episode, the drifts and the flicks, their max |e|, their RMS sideslip error ("-" where no completed episode
    drove the group, or a summary made before it was measured)."""
    groups = [summary.get("by_phase", {}).get(group, {}) for group in PHASE_GROUPS]
    means = [summary.get("mean_abs_e_m"), *(g.get("mean_abs_e_m") for g in groups)]
    return " | ".join([" / ".join(_number(v, 2) for v in means),
                       " / ".join(_number(g.get("max_abs_e_m"), 2) for g in groups),
                       " / ".join(_number(g.get("rms_beta_err_rad"), 3) for g in groups)])


def _number(value: float | None, digits: int) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def _verdict(learned: dict, untuned: dict, n_evaluations: int, seed_points: int = 20) -> list[str]:
    """Say plainly when the learned theta does not beat the untuned one on fresh seeds."""
    worse_j = learned["J_mean"] > untuned["J_mean"]
    less_robust = learned["completion_rate"] < untuned["completion_rate"]
    if not (worse_j or less_robust):
        return ["", f"The learned theta beats the untuned one on fresh seeds (J mean {learned['J_mean']:.3f} against "
                    f"{untuned['J_mean']:.3f}; lower is better)."]
    what = " and ".join(w for w, bad in (("a worse J", worse_j), ("fewer completed episodes", less_robust)) if bad)
    return ["", f"**Note:** the learned theta scores {what} than the untuned one on fresh seeds. After "
                f"{n_evaluations} evaluations the optimizer has mostly explored (the first {seed_points} are "
                "space-filling points); the paper runs 500. Continue the job "
                "(`driftlab tune --name NAME --iterations 500`) and report again."]
