"""Every speed figure of DriftLab in one run, each also as a ratio to a fixed pure-Python calibration loop timed
in the same run (these machines are shared and noisy: compare ratios across machines and days, seconds
within one run).

Figures: warm episode on one core (default plant, median of 15), cold `driftlab episode` (a new process, median
of 3), ask+tell at n = 400 (median and worst of 31 consecutive, three refits of each model among them; and the
first ask after a rebuild from stored history, which fits both), the
paper's 500-run (500 iterations, 20 seed points, active set 400, theta's four parameters, 2 workers, one episode per
evaluation) and where its seconds go, and with --robust the job default's 500-run (six dimensions, 12 seed points,
4 + 4 seeds per evaluation).

Run: OMP_NUM_THREADS=1 python benchmarks/bench_all.py [--robust | --robust-only] [--runs 1]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402


def calibration_ms() -> float:
    """A fixed pure-Python loop (integer arithmetic and a dict): median of 5, in ms."""
    def loop() -> int:
        table: dict[int, int] = {}
        total = 0
        for i in range(400_000):
            total += (i * i) % 7
            table[i & 1023] = total
        return total

    times = []
    for _ in range(5):
        t0 = time.perf_counter()
        loop()
        times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times)


def warm_episode_ms() -> float:
    from driftlab.core.config import Theta
    from driftlab.core.configure import preset_config
    from driftlab.core.episode import run_episode

    config = preset_config("default")
    run_episode(Theta(), config)
    times = []
    for seed in range(15):
        t0 = time.perf_counter()
        run_episode(Theta(), config, seed=seed)
        times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times)


def cold_episode_s() -> float:
    times = []
    for _ in range(3):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "driftlab.cli", "episode"], check=True, capture_output=True)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def proposal_ms() -> tuple[float, float, float]:
    sys.path.insert(0, os.path.dirname(__file__))
    from bench_optimizer import BOUNDS, objective

    from driftlab.core.optimizer import BayesianOptimizer

    rng = np.random.default_rng(0)
    opt = BayesianOptimizer(BOUNDS, seed_points=20, active_set=400, seed=0)
    for _ in range(400):
        theta = {k: float(rng.uniform(*b)) for k, b in BOUNDS.items()}
        opt.tell(theta, objective(theta))
    t0 = time.perf_counter()
    theta = opt.ask()  # the first ask after a rebuild fits both models' hyperparameters
    opt.tell(theta, objective(theta))
    first = (time.perf_counter() - t0) * 1e3
    times = []
    for _ in range(31):
        t0 = time.perf_counter()
        theta = opt.ask()
        opt.tell(theta, objective(theta))
        times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times), max(times), first


class _Timer:
    """Wraps a callable and sums the seconds spent in it."""

    def __init__(self, owner, name: str) -> None:
        self.owner, self.name, self.original, self.seconds, self.calls = owner, name, getattr(owner, name), 0.0, 0
        timer = self

        def timed(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return timer.original(*args, **kwargs)
            finally:
                timer.seconds += time.perf_counter() - t0
                timer.calls += 1

        setattr(owner, name, timed)

    def restore(self) -> None:
        setattr(self.owner, self.name, self.original)


def tuning_run(robust: bool, prune: str | None = None, seed: int = 0, iterations: int = 500,
               rescore: int = 0) -> dict[str, float]:
    """A whole job as `driftlab tune` runs it, with the main process's time split by where it goes. ``prune``
    (robust only): "off", or "CONFIDENCE,MIN_SEEDS" (None: the job default's rule); ``rescore``: its best theta's
    completion and mean J on that many fresh seeds (driftlab.core.robust.rescore_seeds), after the timed run."""
    from driftlab.core.optimizer import BayesianOptimizer
    from driftlab.core.pruning import PruneRule
    from driftlab.core.robust import rescore_seeds, summarize
    from driftlab.core.tuning import PAPER_PRESET, TuningSpec
    from driftlab.db import lifecycle, storage
    from driftlab.worker import job_loop
    from driftlab.worker.executors import LocalProcessExecutor
    from driftlab.worker.scoring import score_thetas

    # Robust: the job default (six dimensions, 4 + 4 seeds, its local phase); otherwise the paper's 500-run.
    rule = (PruneRule() if prune is None else PruneRule(enabled=False) if prune == "off" else
            PruneRule(confidence=float(prune.split(",")[0]), min_seeds=int(prune.split(",")[1])))
    spec = (TuningSpec(iterations=iterations, seed=seed, prune=rule) if robust else
            TuningSpec(**{**PAPER_PRESET, "iterations": iterations}, seed=seed, robust_samples=1, confirm_samples=0))
    with tempfile.TemporaryDirectory() as folder:
        t0 = time.perf_counter()
        factory = storage.open_database(f"sqlite:///{folder}/bench.db")
        runner = lifecycle.new_runner_id("bench")
        with storage.transaction(factory) as session:
            job_id = storage.create_job(session, name="bench", spec=spec.to_dict(), seed=0).id
        job_loop.claim_job(factory, job_id, runner)
        executor = LocalProcessExecutor(2)
        executor.warm_up().result()
        startup = time.perf_counter() - t0
        timers = [_Timer(BayesianOptimizer, "ask"), _Timer(BayesianOptimizer, "tell"), _Timer(job_loop, "_store")]
        episode_ms: list[float] = []
        original_submit = executor.submit

        def submit(*args, **kwargs):
            future = original_submit(*args, **kwargs)
            future.add_done_callback(lambda f: episode_ms.append(f.result().wall_ms))
            return future

        executor.submit = submit
        t1 = time.perf_counter()
        try:
            job_loop.run_job(factory, job_id, executor, runner=runner, workers=2)
            loop_s = time.perf_counter() - t1
            for timer in timers:
                timer.restore()
            executor.submit = original_submit
            with storage.snapshot(factory) as session:
                stored = storage.evaluations(session, job_id=job_id)
                best = storage.best_evaluation(session, job_id=job_id)
            fresh = (summarize(score_thetas(executor, [dict(best.theta)], spec.to_dict()["config"],
                                            rescore_seeds(rescore))[0]) if rescore and best is not None else None)
        finally:
            for timer in timers:
                timer.restore()
            executor.shutdown()
    ask, tell, store = timers
    return {"startup_s": startup, "loop_s": loop_s, "wall_s": startup + loop_s, "ask_s": ask.seconds,
            "tell_s": tell.seconds, "store_s": store.seconds, "episodes": len(episode_ms),
            "episode_cpu_s": sum(episode_ms) / 1e3, "evaluations": len(stored),
            "episodes_per_evaluation": len(episode_ms) / max(len(stored), 1),
            "failed": sum(not e.completed for e in stored),
            "pruned": sum(bool((e.metrics or {}).get("pruned")) for e in stored),
            "best_J": best.J if best is not None and best.completed else float("nan"),
            "fresh_completion": fresh["completion_rate"] if fresh else float("nan"),
            "fresh_J": fresh["J_mean"] if fresh else float("nan")}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--robust", action="store_true", help="also the 500-run with robust evaluation")
    parser.add_argument("--runs", type=int, default=1, help="500-runs to take the median of")
    parser.add_argument("--robust-only", action="store_true",
                        help="only the job default's 500-run (implies --robust; skips the other figures)")
    parser.add_argument("--prune", default=None, metavar="off|CONFIDENCE,MIN_SEEDS",
                        help="the robust run's prune rule (default: the job default's, driftlab.core.pruning)")
    parser.add_argument("--seed", type=int, default=0, help="the job seed of the 500-runs")
    parser.add_argument("--iterations", type=int, default=500, help="the 500-runs' budget")
    parser.add_argument("--rescore", type=int, default=0, metavar="N",
                        help="also each robust run's best theta on N fresh seeds (completion, mean J)")
    args = parser.parse_args()
    args.robust = args.robust or args.robust_only
    cal = calibration_ms()
    print(f"calibration loop: {cal:.1f} ms (every ratio below is figure / this)")

    def show(label: str, value: float, unit: str, target: str) -> None:
        scale = 1e3 if unit == "s" else 1.0
        print(f"  {label:44s} {value:8.3f} {unit:2s}  ratio {value * scale / cal:7.2f}   target {target}")

    if not args.robust_only:
        show("warm episode, default plant (median of 15)", warm_episode_ms(), "ms", "<= 20 ms")
        show("cold `driftlab episode` (median of 3)", cold_episode_s(), "s", "<= 1.5 s")
        median, worst, first = proposal_ms()
        show("ask+tell at n = 400, median of 31", median, "ms", "<= 30 ms")
        show("ask+tell at n = 400, worst of 31 (3+3 refits)", worst, "ms", "<= 100 ms")
        show("first ask+tell after a resume at n = 400", first, "ms", "(both refits at once)")
    for robust in ([True] if args.robust_only else [False, True] if args.robust else [False]):
        runs = [tuning_run(robust, args.prune if robust else None, args.seed, args.iterations,
                           args.rescore if robust else 0) for _ in range(args.runs)]
        run = {k: statistics.median(r[k] for r in runs) for k in runs[0]}
        name = "job default, 4+4 seeds" if robust else "paper's, one episode per evaluation"
        show(f"500-run, 2 workers, {name}", run["wall_s"], "s", "<= 20 s" if robust else "<= 40 s")
        print(f"    where it goes: start-up {run['startup_s']:.1f} s (database, 2 worker processes); job loop "
              f"{run['loop_s']:.1f} s, of which in the main process: ask {run['ask_s']:.1f} s, tell "
              f"{run['tell_s']:.2f} s, storage {run['store_s']:.1f} s, the rest waiting for episodes; "
              f"{run['episodes']:.0f} episodes took {run['episode_cpu_s']:.1f} s in the workers "
              f"({run['episode_cpu_s'] / 2:.1f} s per worker)")
        # Each run's own figures too: a median of 3 hides whether the runs agreed.
        print(f"    episodes per evaluation {run['episodes_per_evaluation']:.2f} ({run['episodes']:.0f} over "
              f"{run['evaluations']:.0f}; {run['failed']:.0f} failed, {run['pruned']:.0f} pruned), best J "
              f"{run['best_J']:.4f}; each run: " + ", ".join(
                  f"{r['wall_s']:.1f} s / {r['episodes_per_evaluation']:.2f} ep/eval / J {r['best_J']:.4f}"
                  for r in runs))
        if robust and args.rescore:
            print("    its best theta on " + str(args.rescore) + " fresh seeds, each run: " + ", ".join(
                f"completion {r['fresh_completion']:.2f} / mean J {r['fresh_J']:.4f}" for r in runs))


if __name__ == "__main__":
    main()
