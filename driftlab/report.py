"""`driftlab report`: the paper's results for a finished tuning job (markdown, figures, baselines)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from driftlab.core.config import PAPER_THETA, Theta
from driftlab.core.episode import run_episode
from driftlab.core.equilibrium import drift_equilibrium
from driftlab.core.track import FigureEight
from driftlab.core.tuning import TuningSpec
from driftlab.core.vehicle import pack_params
from driftlab.db import storage
from driftlab.plotting import plot_convergence, plot_episode
from driftlab.worker.executor import LocalProcessExecutor

# The paper's Table I (left-hand drift at R = 44 m, beta = -0.4; REFERENCE.md section 2).
PAPER_TABLE_I = {"V": 19.1, "beta": -0.4, "r": 0.434, "delta": -0.270, "Fxr": 4324.0}


def write_report(*, db_url: str, name: str, out_dir: str, baseline_samples: int | None = None) -> Path:
    factory = storage.open_database(db_url)
    with storage.transaction(factory) as session:
        job = storage.find_job(session, name=name)
        if job is None:
            raise storage.NotFound(f"no job named {name!r}")
        spec = TuningSpec.from_dict(job.spec)
        evals = storage.evaluations(session, job_id=job.id)
        best = storage.best_evaluation(session, job_id=job.id)
    if best is None:
        raise storage.NotFound(f"job {name!r} has no evaluations yet")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    config = spec.config
    track = FigureEight(config.scenario.left_radius_m, config.scenario.right_radius_m)
    best_result = run_episode(Theta.from_mapping(best.theta), config)
    plot_episode(best_result, track, str(out / "best_episode.png"),
                 title=f"{name}: best evaluation #{best.index}, {best.status}, J = {best.J:.3f}")
    values = np.array([e.J for e in evals])
    failed = np.array([not e.completed for e in evals])
    plot_convergence(values, failed, str(out / "convergence.png"), title=f"{name}: J per iteration")

    n_random = baseline_samples or len(evals)
    rng = np.random.default_rng(spec.seed + 12345)
    samples = [{k: float(rng.uniform(lo, hi)) for k, (lo, hi) in spec.bounds.items()} for _ in range(n_random)]
    config_doc = spec.to_dict()["config"]
    executor = LocalProcessExecutor(workers=2)
    try:
        futures = [executor.submit(theta, config_doc) for theta in
                   (Theta().as_dict(), PAPER_THETA.as_dict(), *samples)]
        untuned, paper, *scored = [(o.theta, o.status, o.J) for o in (f.result() for f in futures)]
    finally:
        executor.shutdown()
    random_best = min(scored, key=lambda s: s[2])

    eq = drift_equilibrium(config.scenario.left_radius_m, -abs(config.scenario.sideslip_rad),
                           pack_params(config.vehicle)).as_dict()
    lines = [f"# DriftLab report: {name}", "",
             f"{len(evals)} evaluations ({int((~failed).sum())} completed), seed points {spec.seed_points}, "
             f"active set {spec.active_set}, bounds {spec.bounds}.", "",
             "## Drift equilibria (R = 44 m) and learned parameters", "",
             "| | V (m/s) | beta (rad) | r (rad/s) | delta (rad) | Fxr (N) |", "|---|---|---|---|---|---|",
             "| paper Table I | {V} | {beta} | {r} | {delta} | {Fxr} |".format(**PAPER_TABLE_I),
             "| DriftLab model | {V:.3f} | {beta:.4f} | {r:.4f} | {delta:.4f} | {Fxr:.0f} |".format(**eq), "",
             "| theta | c_lr | c_rl | dV (m/s) | k (rad/m) | status | J |", "|---|---|---|---|---|---|---|"]
    for label, theta, status, value in (("learned (best)", best.theta, best.status, best.J),
                                        ("untuned", *untuned), ("paper's", *paper),
                                        (f"best of {n_random} random", *random_best)):
        lines.append(f"| {label} | {theta['c_lr']:.4f} | {theta['c_rl']:.4f} | {theta['dV']:.3f} | "
                     f"{theta['k']:.4f} | {status} | {value:.3f} |")
    lines += ["", "![best episode](best_episode.png)", "", "![convergence](convergence.png)", ""]
    path = out / "report.md"
    path.write_text("\n".join(lines))
    return path
