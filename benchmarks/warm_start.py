"""A warm start that continues a job of the same config, against a cold start, on the drift objective itself.

A source job (the job default: six dimensions, its local phase, ``--robust-samples`` seeded episodes an evaluation,
confirmation seeds off so that every evaluation costs the same episodes) runs ``--source-evaluations``
evaluations once. Then, per BO seed, two jobs of the same config run ``--evaluations`` evaluations each:

- ``cold``: no warm start;
- ``warm``: the source's evaluations told first (driftlab.core.warm_start, as ``warm_start_from`` does).

Printed per method: the median over BO seeds of the best completed J among the job's own evaluations after each
checkpoint (lower is better), its quartiles, and, for the warm start, the best J the job shows counting the
source's best it starts from. Each job's own evaluations run on its own episode seeds (driftlab.core.robust
.tuning_seeds of its seed), as the jobs would.

Run: OMP_NUM_THREADS=1 python benchmarks/warm_start.py [--seeds 10] [--evaluations 50] [--source-evaluations 40]
     [--checkpoints 15,30,50] [--processes 2]
"""

from __future__ import annotations

import argparse
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace

import numpy as np

os.environ.setdefault("OMP_NUM_THREADS", "1")

SOURCE_SEED = 1000  # the source job's seed: none of the compared jobs' seeds


def _spec(seed: int, robust_samples: int, told=()):
    from driftlab.core.tuning import TuningSpec
    from driftlab.core.warm_start import Observation, WarmStart

    spec = TuningSpec(seed=seed, robust_samples=robust_samples, confirm_samples=0)
    if told:
        spec = replace(spec, warm_start=WarmStart({0: "told"}, tuple(Observation(t, v, j) for t, v, j in told)))
    return spec


def _run_job(spec, evaluations: int) -> tuple[list[tuple[dict, float | None, float]], list[float]]:
    """A job of ``spec``, sequential: its evaluations (theta, J or None, stored J) and its own best after each."""
    from driftlab.worker.optimizer_host import restore_optimizer

    optimizer = restore_optimizer(spec, [])
    from peers import _objective  # the job default's objective, on the job's own episode seeds

    evaluate = _objective(spec.robust_samples, spec.seed)
    history, trace, best = [], [], np.inf
    for _ in range(evaluations):
        theta = optimizer.ask()
        value, stored = evaluate(theta)
        optimizer.tell(theta, value, stored)
        history.append((theta, value, stored))
        best = min(best, value) if value is not None else best
        trace.append(best)
    return history, trace


def _compare(args: tuple[int, int, int, list]) -> tuple[int, dict[str, list[float]]]:
    seed, evaluations, robust_samples, told = args
    traces = {"cold": _run_job(_spec(seed, robust_samples), evaluations)[1],
              "warm": _run_job(_spec(seed, robust_samples, told), evaluations)[1]}
    return seed, traces


def _quantiles(values: list[float]) -> str:
    q1, q2, q3 = np.quantile([v if np.isfinite(v) else 1e9 for v in values], [0.25, 0.5, 0.75])
    return "     none" if q2 >= 1e9 else f"{q2:9.3f} [{q1:.3f}, {q3:.3f}]"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--evaluations", type=int, default=50)
    parser.add_argument("--source-evaluations", type=int, default=40)
    parser.add_argument("--robust-samples", type=int, default=4)
    parser.add_argument("--checkpoints", default="15,30,50")
    parser.add_argument("--processes", type=int, default=2)
    args = parser.parse_args()
    checkpoints = [int(c) for c in args.checkpoints.split(",")]
    told, source_trace = _run_job(_spec(SOURCE_SEED, args.robust_samples), args.source_evaluations)
    source_best = source_trace[-1]
    print(f"source job (seed {SOURCE_SEED}): {args.source_evaluations} evaluations, best J {source_best:.3f}")
    with ProcessPoolExecutor(args.processes) as pool:
        results = dict(pool.map(_compare, [(s, args.evaluations, args.robust_samples, told)
                                           for s in range(args.seeds)]))
    print(f"median best J of the job's own evaluations over {args.seeds} BO seeds [quartiles]; lower is better")
    print(f"{'method':10}" + "".join(f"{'after ' + str(c):>28}" for c in checkpoints))
    for method in ("cold", "warm"):
        cells = [_quantiles([results[s][method][c - 1] for s in results]) for c in checkpoints]
        print(f"{method:10}" + "".join(f"{cell:>28}" for cell in cells))
    for method in ("warm",):
        cells = [_quantiles([min(results[s][method][c - 1], source_best) for s in results]) for c in checkpoints]
        print(f"{method + '*':10}" + "".join(f"{cell:>28}" for cell in cells))
    print("*: the best the job shows, counting the source's best it starts from")


if __name__ == "__main__":
    main()
