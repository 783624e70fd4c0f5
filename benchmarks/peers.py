"""Sample efficiency on the drift objective itself: DriftLab's optimizer against Optuna's TPESampler and GPSampler
and uniform random search, side by side.

Every method sees the same objective: a theta in the default bounds scored as a tuning job scores it (the
default plant, ``--robust-samples`` seeded episodes with common random numbers, failed episodes at their
penalty; confirmation seeds off, so every evaluation costs the same episodes). DriftLab is told a failed
evaluation as failed (its interface); the peers get the penalized mean (theirs: a number). Printed: the median
over BO seeds of the best completed J after 25, 50 and 100 evaluations (lower is better), its quartiles, and
the CPU seconds a run took (episodes included).

Optuna is a benchmark-only extra (``pip install optuna torch``; its GPSampler needs torch), never a runtime
dependency.

Run: OMP_NUM_THREADS=1 python benchmarks/peers.py [--seeds 6] [--evaluations 100] [--methods driftlab,tpe,gp,random]
     [--plant plant.friction_scale=0.93 ...]
     (``driftlab``: the job default; ``driftlab-s=N``: with N space-filling points, e.g. driftlab-s=20 for the
     paper's 20, ``-l=N`` of them local around the untuned theta (``-l=0``: no local phase), ``-r=R`` the local
     box's half-width in unit widths, ``-m=R`` instead: R for the model corrections only, the four others over their
     whole range, ``-g=N`` the GP's proposals in that box grown to the whole over N evaluations; a ``+mc``
     suffix, e.g. ``driftlab+mc,tpe+mc``: the job's default box with the model corrections, six dimensions)
"""

from __future__ import annotations

import argparse
import os
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

os.environ.setdefault("OMP_NUM_THREADS", "1")

CHECKPOINTS = (25, 50, 100)


def _objective(robust_samples: int, bo_seed: int, plant: tuple[str, ...] = ()):
    """theta dict -> (J or None if the evaluation failed, penalized J); ``plant``: key=value overrides of the
    default plant (a plant drawn away from it)."""
    from driftlab.core.config import Theta
    from driftlab.core.configure import apply_overrides, preset_config
    from driftlab.core.episode import run_episode
    from driftlab.core.robust import SampleResult, aggregate, tuning_seeds

    config = apply_overrides(preset_config("default"),
                             {k: float(v) for k, v in (item.split("=") for item in plant)})
    seeds = tuning_seeds(bo_seed, robust_samples)

    def evaluate(theta: dict[str, float]) -> tuple[float | None, float]:
        samples = []
        for seed in seeds:
            r = run_episode(Theta.from_mapping(theta), config, seed=seed)
            samples.append(SampleResult(seed, r.status, r.J, r.metrics.completed_fraction, None))
        score = aggregate(samples)
        return (score.J if score.status == "completed" else None), score.J

    return evaluate


def _run(args: tuple[str, int, int, int, tuple[str, ...]]) -> tuple[str, int, list[float], float]:
    """One optimizer run: (method, seed, best completed J after each evaluation, CPU seconds)."""
    label, bo_seed, evaluations, robust_samples, plant = args
    from driftlab.core.tuning import DEFAULT_BOUNDS, MODEL_BOUNDS, TuningSpec

    evaluate = _objective(robust_samples, bo_seed, plant)
    method, six = label.removesuffix("+mc"), label.endswith("+mc")
    bounds = {**DEFAULT_BOUNDS, **MODEL_BOUNDS} if six else DEFAULT_BOUNDS
    trace: list[float] = []
    best = np.inf
    started = time.process_time()
    if method.startswith("driftlab"):
        from driftlab.core.optimizer import BayesianOptimizer

        # "driftlab": the job default (six dimensions: with its local phase); options change it, e.g.
        # driftlab-l=0 (no local phase), driftlab-s=12-l=5-r=0.15, driftlab-l=11-m=0.05-g=15
        options = dict(part.split("=") for part in method.split("-")[1:])
        settings = TuningSpec(seed=bo_seed, model_correction=six).optimizer_options
        if "s" in options:
            settings["seed_points"] = int(options["s"])
        if "l" in options:
            settings.update(local_points=int(options["l"]), local_radius=float(options.get("r", 0.15)),
                            local_growth=int(options.get("g", 0)))
            if "m" in options:  # the model corrections near the untuned model, the paper's four over their range
                settings["local_radius"] = {name: float(options["m"]) for name in MODEL_BOUNDS}
        opt = BayesianOptimizer(bounds, **settings)
        for _ in range(evaluations):
            theta = opt.ask()
            value, _ = evaluate(theta)
            opt.tell(theta, value)
            best = min(best, value) if value is not None else best
            trace.append(best)
    elif method == "random":
        rng = np.random.default_rng(bo_seed)
        for _ in range(evaluations):
            value, _ = evaluate({k: float(rng.uniform(*b)) for k, b in bounds.items()})
            best = min(best, value) if value is not None else best
            trace.append(best)
    else:
        import optuna

        optuna.logging.set_verbosity(optuna.logging.WARNING)
        sampler = (optuna.samplers.TPESampler(seed=bo_seed) if method == "tpe"
                   else optuna.samplers.GPSampler(seed=bo_seed))
        study = optuna.create_study(sampler=sampler, direction="minimize")

        def objective(trial):
            nonlocal best
            theta = {k: trial.suggest_float(k, *b) for k, b in bounds.items()}
            value, penalized = evaluate(theta)
            best = min(best, value) if value is not None else best
            trace.append(best)
            return penalized

        study.optimize(objective, n_trials=evaluations)
    return label, bo_seed, trace, time.process_time() - started


_NONE = 1e9  # stands for "no completed evaluation yet" in the quantiles


def _cell(value: float, spec: str) -> str:
    return "none" if value >= _NONE / 100 else format(value, spec)  # interpolated towards a run with none


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--seeds", type=int, default=6)
    parser.add_argument("--evaluations", type=int, default=100)
    parser.add_argument("--robust-samples", type=int, default=4)
    parser.add_argument("--methods", default="driftlab,tpe,gp,random")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--plant", nargs="*", default=[], metavar="KEY=VALUE",
                        help="the default plant changed, e.g. plant.friction_scale=0.93 plant.steer_lag_s=0.08")
    args = parser.parse_args()
    methods = args.methods.split(",")
    plant = tuple(args.plant)
    jobs = [(m, s, args.evaluations, args.robust_samples, plant) for s in range(args.seeds) for m in methods]
    with ProcessPoolExecutor(args.workers) as pool:
        results = list(pool.map(_run, jobs))
    points = [c for c in CHECKPOINTS if c <= args.evaluations]
    plant_text = " with " + " ".join(plant) if plant else ""
    print(f"drift objective, default plant{plant_text} and bounds, {args.robust_samples} episodes per evaluation, "
          f"{args.seeds} seeds; best completed J (median [q25, q75]) after n evaluations; lower is better")
    print("| method | " + " | ".join(f"n = {c}" for c in points) + " | CPU s per run |")
    print("|---|" + "---|" * (len(points) + 1))
    for method in methods:
        runs = [r for r in results if r[0] == method]
        cells = []
        for c in points:
            # a run with no completion yet has best inf: it ranks last, and a quantile that lands on it says "none"
            values = np.minimum(np.array([r[2][c - 1] for r in runs]), _NONE)
            q25, med, q75 = np.percentile(values, [25, 50, 75])
            cells.append(f"{_cell(med, '.3f')} [{_cell(q25, '.2f')}, {_cell(q75, '.2f')}]")
        cpu = np.median([r[3] for r in runs])
        print(f"| {method} | " + " | ".join(cells) + f" | {cpu:.1f} |")


if __name__ == "__main__":
    main()
