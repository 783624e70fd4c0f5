"""Evaluations per second on a real local Dask cluster (`dask scheduler` + N `dask worker` processes, one thread
each) for N = 1, 2, 4, with a headless `driftlab tune --dask`; the local process pool beside it.

Two figures per N: space-filling only (seed points = iterations: the episodes' throughput) and with the GP
from evaluation 20 on (what a job gets). Rates over the evaluations after the first 10 (workers warm).

Run: OMP_NUM_THREADS=1 python benchmarks/bench_dask.py [--workers 1 2 4] [--iterations 80]
"""

import argparse
import json
import os
import socket
import subprocess
import sys
import tempfile
import time

from driftlab.db import storage

BIN = os.path.dirname(sys.executable)
ENV = {**os.environ, "OMP_NUM_THREADS": "1", "PATH": BIN + os.pathsep + os.environ["PATH"]}


def _port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _start_cluster(n: int) -> tuple[str, list[subprocess.Popen]]:
    from distributed import Client

    port = _port()
    address = f"tcp://127.0.0.1:{port}"
    procs = [subprocess.Popen(["dask", "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                              env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    time.sleep(2.0)
    procs += [subprocess.Popen(["dask", "worker", address, "--nthreads", "1", "--no-nanny", "--no-dashboard"],
                               env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL) for _ in range(n)]
    with Client(address, timeout=30, set_as_default=False) as client:
        client.wait_for_workers(n, timeout=120)
    return address, procs


def _rate(db: str, name: str, skip: int = 10) -> float:
    factory = storage.open_database(f"sqlite:///{db}")
    with storage.transaction(factory) as session:
        job = storage.find_job(session, name=name)
        stamps = [e.created_at for e in storage.evaluations(session, job_id=job.id)][skip:]
    return (len(stamps) - 1) / (stamps[-1] - stamps[0]).total_seconds()


def _tune(db: str, name: str, iterations: int, seed_points: int, extra: list[str]) -> None:
    subprocess.run([sys.executable, "-m", "driftlab.cli", "tune", "--db", db, "--name", name, "--iterations",
                    str(iterations), "--seed-points", str(seed_points), "--robust-samples", "1",
                    "--confirm-samples", "0", *extra], env=ENV, check=True, capture_output=True)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2, 4])
    parser.add_argument("--iterations", type=int, default=80)
    args = parser.parse_args()
    db = os.path.join(tempfile.mkdtemp(), "bench.db")
    rows = []
    for n in args.workers:
        address, procs = _start_cluster(n)
        try:
            for label, seed_points in (("episodes only", args.iterations), ("with GP", 20)):
                name = f"dask{n}-{seed_points}"
                _tune(db, name, args.iterations, seed_points, ["--dask", address])
                rows.append({"executor": f"dask, {n} worker(s)", "mode": label, "eval_per_s": _rate(db, name)})
                print(json.dumps(rows[-1]), flush=True)
        finally:
            for proc in procs:
                proc.kill()
                proc.wait()
    for n in (1, 2):
        for label, seed_points in (("episodes only", args.iterations), ("with GP", 20)):
            name = f"local{n}-{seed_points}"
            _tune(db, name, args.iterations, seed_points, ["--workers", str(n)])
            rows.append({"executor": f"local pool, {n} process(es)", "mode": label, "eval_per_s": _rate(db, name)})
            print(json.dumps(rows[-1]), flush=True)
    print("| executor | mode | evaluations/s |\n|---|---|---|")
    for r in rows:
        print(f"| {r['executor']} | {r['mode']} | {r['eval_per_s']:.1f} |")


if __name__ == "__main__":
    main()
