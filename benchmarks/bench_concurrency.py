"""Throughput of an 8-job seeds study against the number of workers: its jobs one after another (as a study ran
before: claim a job, run it to the end, then the next) against the server's job runner running them at once on the
shared executor (driftlab.worker.job_runner, driftlab.worker.slots). Real SQLite file (or --db: PostgreSQL), the
real job loop and optimizer (the job default: six dimensions, 4 + 4 robust seeds), every evaluation committed as it
completes.

(a) A simulated cluster: a fake executor whose episodes sleep 16 ms on a pool of N threads ("workers"), N = 1 ... 32;
    each episode returns a real episode's trajectory (so a commit stores what a real one does).
(b) 2 real local workers (the process pool, real episodes): 8 jobs x 6 evaluations, 2 + 1 robust seeds.

Per evaluation it measures the ask (the job's optimizer: in the job's thread one after another; in the server's
optimizer host process at once, timed as the job's thread waits for it) and the store (one write
transaction: the evaluation, its trajectory), and prints their medians, with how busy each resource was:
"job" the busiest job thread's share of the wall time spent asking, telling and storing (near 100 %: that job's
optimizer is the limit), "db" the write transactions' share of the wall time (near 100 %: storage is), "work" the
workers' (episode time / (N x wall)), and "cpu" this process's CPU seconds per wall second (2 cores here). The
summary adds the workers' share while all 8 jobs still run (until the first job's last store): the capacity the
server keeps in use, apart from the study's drain, where the jobs left have fewer evaluations in flight than workers.

Run: OMP_NUM_THREADS=1 python benchmarks/bench_concurrency.py [--workers 1 2 4 8 16 32] [--evaluations 30]
     [--real-evaluations 6] [--real-repeats 3] [--skip-real] [--skip-simulated] [--optimizer-process] [--db URL]
"""

from __future__ import annotations

import argparse
import gc
import os
import statistics
import tempfile
import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import replace
from math import nan

os.environ.setdefault("OMP_NUM_THREADS", "1")

from driftlab.core.tuning import DEFAULT_ROBUST_SAMPLES, TuningSpec  # noqa: E402
from driftlab.db import storage, studies  # noqa: E402
from driftlab.services.studies import start_study  # noqa: E402
from driftlab.worker import job_loop  # noqa: E402
from driftlab.worker.executors import EpisodeOutcome, LocalProcessExecutor, evaluate_episode  # noqa: E402
from driftlab.worker.job_loop import claim_job, run_job  # noqa: E402
from driftlab.worker.job_runner import JobRunner  # noqa: E402
from driftlab.worker.optimizer_host import OptimizerHost  # noqa: E402

SEEDS = list(range(8))
EPISODE_S = 0.016


class SleepingCluster:
    """N "workers": episodes that sleep ``episode_s`` and return ``template`` with a J that depends on theta."""

    def __init__(self, workers: int, template: EpisodeOutcome, episode_s: float = EPISODE_S) -> None:
        self.workers, self.template, self.episode_s = workers, template, episode_s
        self.pool = ThreadPoolExecutor(workers)
        self.cpu_s = 0.0  # CPU its episodes took in this process (a real cluster's run elsewhere)
        self.starts_s: list[float] = []  # each episode's start (perf_counter)
        self._lock = threading.Lock()

    def _episode(self, theta, seed) -> EpisodeOutcome:
        cpu0 = time.thread_time()
        self.starts_s.append(time.perf_counter())
        time.sleep(self.episode_s)
        j = sum((v - 0.5) ** 2 for v in theta.values()) + 0.01 * (seed % 7) - 2.0
        outcome = replace(self.template, theta=dict(theta), seed=seed, J=j, wall_ms=self.episode_s * 1000)
        with self._lock:
            self.cpu_s += time.thread_time() - cpu0
        return outcome

    def submit(self, theta, config_doc, seed=0) -> Future:
        return self.pool.submit(self._episode, theta, seed)

    def shutdown(self) -> None:
        self.pool.shutdown(wait=True)


class Meter:
    """Times every ask, tell and store of the job loop (per job thread), wrapped around the real ones."""

    def __init__(self) -> None:
        self.ask_s: list[float] = []
        self.store_s: list[float] = []
        self.thread_s: dict[int, float] = {}
        self.last_store_s: dict[int, float] = {}  # per job: when its latest store ended (perf_counter)
        self._real_restore, self._real_store = job_loop.restore_optimizer, job_loop._store
        self._real_open = OptimizerHost.open

    def _add(self, seconds: float) -> None:
        key = threading.get_ident()
        self.thread_s[key] = self.thread_s.get(key, 0.0) + seconds

    def __enter__(self) -> Meter:
        meter = self

        def restore(spec, history):
            return timed(meter._real_restore(spec, history))

        def open_in_host(host, spec, history):  # the server's runner: the optimizer in the host process
            return timed(meter._real_open(host, spec, history))

        def timed(optimizer):
            ask, tell = optimizer.ask, optimizer.tell

            def timed_ask():
                t0 = time.perf_counter()
                theta = ask()
                meter.ask_s.append(time.perf_counter() - t0)
                meter._add(meter.ask_s[-1])
                return theta

            def timed_tell(*args):
                t0 = time.perf_counter()
                tell(*args)
                meter._add(time.perf_counter() - t0)

            optimizer.ask, optimizer.tell = timed_ask, timed_tell
            return optimizer

        def store(*args):
            t0 = time.perf_counter()
            out = meter._real_store(*args)
            meter.last_store_s[args[1].job_id] = time.perf_counter()
            meter.store_s.append(time.perf_counter() - t0)
            meter._add(meter.store_s[-1])
            return out

        job_loop.restore_optimizer, job_loop._store = restore, store
        OptimizerHost.open = open_in_host
        return self

    def __exit__(self, *exc) -> None:
        job_loop.restore_optimizer, job_loop._store = self._real_restore, self._real_store
        OptimizerHost.open = self._real_open


DATABASE_URL: str | None = None  # --db: every measurement's study in this database (else an SQLite file each)


def _database(db_dir: str, name: str):
    return storage.open_database(DATABASE_URL or f"sqlite:///{os.path.join(db_dir, name + '.db')}")


def _study(factory, spec: dict):
    with storage.transaction(factory) as session:
        study = start_study(session, doc={"kind": "seeds", "seeds": SEEDS, "spec": spec})
        jobs = [j.id for j in studies.study_jobs(session, study_id=study.id)]
    return study.id, jobs


def _one_after_another(factory, jobs, executor, workers: int) -> None:
    for job_id in jobs:
        claim_job(factory, job_id, "bench")
        status = run_job(factory, job_id, executor, runner="bench", workers=workers)
        if status != "finished":
            with storage.snapshot(factory) as session:
                raise RuntimeError(f"job {job_id} {status}: {storage.get_job(session, job_id=job_id).error}")


class _Lent:
    """The executor for a runner that stops (and would shut it down) while the benchmark still needs it."""

    def __init__(self, executor) -> None:
        self.submit = executor.submit

    def shutdown(self) -> None:
        pass


OPTIMIZER_PROCESS = False  # --optimizer-process: the runner's jobs ask in processes of their own


def started_runner(factory, executor, workers: int) -> JobRunner:
    """The server's runner, started (its optimizer processes answering) before the study it will run exists: a
    server runs many studies, and starts once."""
    runner = JobRunner(factory, workers=workers, optimizer_process=OPTIMIZER_PROCESS)
    runner.start(executor=_Lent(executor))
    if runner.optimizers is not None:
        runner.optimizers.wait_started()
    gc.freeze()  # as the server does once it has started (driftlab.server.app's lifespan)
    return runner


def _at_once(factory, study_id, runner: JobRunner) -> None:
    """Until the study is finished. The wall time ends when its last job does: the runner's jobs are watched in
    memory every 2 ms (a database read every 50 ms added up to 50 ms, 4 % of a 16-worker run), the study's status
    read once they have all stopped."""
    runner.wake()
    seen_running = False
    while True:
        running = bool(runner.running_job_ids)
        seen_running = seen_running or running
        if not running and seen_running:
            with storage.snapshot(factory) as session:
                status = studies.study_status(session, studies.get_study(session, study_id=study_id))
            if status == "finished":
                return
            if status in ("failed", "paused"):
                raise RuntimeError(f"the study is {status}")
            seen_running = False  # jobs still to claim: wait for the runner to start them
        time.sleep(0.002)


def measure(mode: str, db_dir: str, spec: dict, executor, workers: int) -> dict:
    factory = _database(db_dir, f"{mode}-{workers}-{time.monotonic_ns()}")
    runner = started_runner(factory, executor, workers) if mode != "sequential" else None
    study_id, jobs = _study(factory, spec)
    cluster_cpu0 = getattr(executor, "cpu_s", 0.0)
    with Meter() as meter:
        wall0, cpu0, watch0 = time.perf_counter(), time.process_time(), time.thread_time()
        if runner is None:
            _one_after_another(factory, jobs, executor, workers)
            watch_s = 0.0  # this thread runs the jobs: the server's work
        else:
            _at_once(factory, study_id, runner)
            watch_s = time.thread_time() - watch0  # this thread only polls the study's status
        wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    # The server's CPU: this process's, less what stands in for the cluster (its episodes' threads) and the
    # benchmark's own polling for the study's end.
    server_cpu = cpu - (getattr(executor, "cpu_s", 0.0) - cluster_cpu0) - watch_s
    if runner is not None:
        runner.stop()
    with storage.snapshot(factory) as session:
        stored = [storage.evaluations(session, job_id=j) for j in jobs]
    for evaluations in stored:  # numbered once each, none missing
        assert [e.index for e in evaluations] == list(range(spec["iterations"]))
    n = sum(len(evaluations) for evaluations in stored)
    episodes_s = sum(e.wall_ms for evaluations in stored for e in evaluations) / 1000
    # The wall time's floor while each job keeps its even share of the workers: the job with the most episode time
    # on its share (jobs differ by how many thetas are pruned, confirmed or fail, not by their budget).
    busiest_s = max(sum(e.wall_ms for e in evaluations) for evaluations in stored) / 1000
    floor_s = max(busiest_s / max(workers // len(jobs), 1), episodes_s / workers)
    storage.engine_of(factory).dispose()
    steady = _steady_busy(executor, workers, wall0, min(meter.last_store_s.values())) if runner is not None else nan
    return {"wall": wall, "rate": n / wall, "ask_ms": 1000 * statistics.median(meter.ask_s),
            "store_ms": 1000 * statistics.median(meter.store_s),
            "job": max(meter.thread_s.values()) / wall, "db": sum(meter.store_s) / wall, "cpu": cpu / wall,
            "work": episodes_s / (workers * wall), "cpu_ms": 1000 * cpu / n, "server_cpu_ms": 1000 * server_cpu / n,
            "episodes": sum(len(e.seeds or ()) for evaluations in stored for e in evaluations) / n,
            "floor": floor_s, "steady": steady}


def _steady_busy(cluster, workers: int, since_s: float, first_end_s: float) -> float:
    """The workers' busy share while every job of the study still runs (from the study's start to its first job's
    last store): the cluster's capacity the server keeps in use, without the study's drain, where the jobs left
    have fewer evaluations in flight than the workers (the whole study's share counts it)."""
    episode_s = getattr(cluster, "episode_s", None)
    if episode_s is None or first_end_s <= since_s:
        return nan
    starts = [t for t in cluster.starts_s if t >= since_s]
    busy = sum(max(0.0, min(t + episode_s, first_end_s) - t) for t in starts)
    return busy / (workers * (first_end_s - since_s))


def _row(label: str, seq: dict, conc: dict) -> str:
    def part(m: dict) -> str:
        return (f"{m['wall']:7.2f} {m['rate']:7.1f} {m['ask_ms']:6.1f} {m['store_ms']:6.1f} {100 * m['job']:5.0f} "
                f"{100 * m['db']:4.0f} {100 * m['work']:5.0f} {m['cpu']:4.2f}")
    return f"{label:>7} | {part(seq)} | {part(conc)} | {seq['wall'] / conc['wall']:6.2f}x"


HEADER = ("workers |   one job after another                               |   at once (the runner)"
          "                                |\n"
          "        |  wall s  eval/s ask ms st ms  job%  db% work%  cpu |  wall s  eval/s ask ms st ms  job%  db% "
          "work%  cpu | speedup")


def _limits(rows: list[tuple[int, dict, dict]]) -> None:
    """Where each resource runs out: one job's optimizer (its thread busy >= 80 % one after another), storage (the
    write transactions >= 80 % of the wall time at once), the process's CPU."""
    optimizer = next((n for n, seq, _ in rows if seq["job"] >= 0.8), None)
    db = next((n for n, _, conc in rows if conc["db"] >= 0.8), None)
    print(f"\none job's optimizer saturates (its thread >= 80 % busy, jobs one after another) at "
          f"{optimizer if optimizer is not None else 'none of these'} workers; storage (commits >= 80 % of the wall "
          f"time, jobs at once) at {db if db is not None else 'none of these'} workers")
    for n, seq, conc in rows:
        bound = ("the workers" if conc["work"] >= 0.8 else "storage" if conc["db"] >= 0.8
                 else "the jobs' asks (CPU)" if conc["cpu"] >= 0.8 else "latency (asks between rounds)")
        solo = "its optimizer" if seq["job"] >= 0.8 else "the workers" if seq["work"] >= 0.8 else "latency"
        print(f"  {n:>2} workers: one job at a time is bound by {solo}; 8 at once by {bound}")
    print("\nshare of the cluster's capacity (N / (episode s x the job default's 4 seeds) evaluations/s) and the "
          "server's CPU per evaluation (this process's, less the simulated cluster's threads and the benchmark's "
          "polling; the whole process's in brackets), the 8 jobs at once:")
    for n, _, conc in rows:
        capacity = n / (EPISODE_S * DEFAULT_ROBUST_SAMPLES)
        share = 100 * conc["rate"] / capacity
        print(f"  {n:>2} workers: {conc['rate']:6.1f} of {capacity:6.0f} evaluations/s ({share:3.0f} %), "
              f"{conc['server_cpu_ms']:5.1f} ms of the server's CPU an evaluation ({conc['cpu_ms']:.1f}); "
              f"the workers busy {100 * conc['work']:3.0f} % ({100 * conc['steady']:3.0f} % while all 8 jobs run) "
              f"({conc['episodes']:.2f} episodes an evaluation: a would-be best runs its confirmation seeds too); "
              f"the busiest job's episodes on its share of the workers {conc['floor']:.2f} s of the "
              f"{conc['wall']:.2f} s wall")


def simulated(workers: list[int], evaluations: int, db_dir: str) -> None:
    template = evaluate_episode({}, TuningSpec().to_dict()["config"], 0)  # a real episode's trajectory
    spec = {"iterations": evaluations}
    print(f"(a) simulated cluster: 8 jobs x {evaluations} evaluations (job default: 6 dimensions, 4 + 4 robust "
          f"seeds), episodes sleep {EPISODE_S * 1000:.0f} ms, trajectory {template.trajectory.shape}\n{HEADER}")
    rows = []
    for n in workers:
        cluster = SleepingCluster(n, template)
        seq = measure("sequential", db_dir, spec, cluster, n)
        conc = measure("concurrent", db_dir, spec, cluster, n)
        cluster.shutdown()
        rows.append((n, seq, conc))
        print(_row(str(n), seq, conc), flush=True)
    _limits(rows)


def real(evaluations: int, db_dir: str, repeats: int) -> None:
    spec = {"iterations": evaluations, "robust_samples": 2, "confirm_samples": 1}
    executor = LocalProcessExecutor(2)
    executor.warm_up().result()
    print(f"\n(b) 2 real local workers (process pool): 8 jobs x {evaluations} evaluations, 2 + 1 robust seeds, "
          f"median of {repeats}\n{HEADER}")
    try:
        runs = [(measure("sequential", db_dir, spec, executor, 2), measure("concurrent", db_dir, spec, executor, 2))
                for _ in range(repeats)]
    finally:
        executor.shutdown()
    median = {mode: {k: statistics.median(r[i][k] for r in runs) for k in runs[0][i]} for i, mode in enumerate("sc")}
    print(_row("2", median["s"], median["c"]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2, 4, 8, 16, 32])
    parser.add_argument("--evaluations", type=int, default=30)
    parser.add_argument("--real-evaluations", type=int, default=6)
    parser.add_argument("--real-repeats", type=int, default=3)
    parser.add_argument("--skip-real", action="store_true")
    parser.add_argument("--skip-simulated", action="store_true")
    parser.add_argument("--db", help="an SQLAlchemy URL every study is stored in, e.g. a PostgreSQL database "
                                     "(postgresql+psycopg://...); default: a new SQLite file per measurement")
    parser.add_argument("--optimizer-process", action="store_true",
                        help="the runner's jobs ask in processes of their own (DRIFTLAB_OPTIMIZER_PROCESS=1)")
    args = parser.parse_args()
    global DATABASE_URL, OPTIMIZER_PROCESS
    DATABASE_URL, OPTIMIZER_PROCESS = args.db, args.optimizer_process
    print(f"storage: {storage.open_database(args.db).kw['bind'].dialect.name if args.db else 'sqlite'}; the jobs "
          f"ask {'in processes of their own' if args.optimizer_process else 'on their threads'} (at once)")
    with tempfile.TemporaryDirectory() as db_dir:
        if not args.skip_simulated:
            simulated(args.workers, args.evaluations, db_dir)
        if not args.skip_real:
            real(args.real_evaluations, db_dir, args.real_repeats)


if __name__ == "__main__":
    main()
