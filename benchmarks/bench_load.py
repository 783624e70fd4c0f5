"""The service under load while a job runs: 26 readers and 4 writers against a real server whose job runs its
episodes on 2 worker processes. Prints, per kind of request, the count, 5xx count and the p50/p95/p99 latency.

Readers cycle through what a dashboard and a script read (health, jobs, the running job, its evaluations since a
point, its best, one trajectory); writers create a small job, raise its budget, pause it and delete it.

Run: python benchmarks/bench_load.py [--seconds 120] [--readers 26] [--writers 4] [--workers 2] [--processes]
--db FILE --read-job ID: the readers read a stored job of a copy of FILE (a 500-evaluation job's full list is
~750 kB of JSON) while a new job runs.
--processes: each client a process of its own (30 Python processes on the same 2 cores, as 30 separate scripts
would be), instead of 30 concurrent clients in one event loop.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import shutil
import statistics
import tempfile
import time
from collections import defaultdict

import httpx
from served import served


def _percentile(values: list[float], q: float) -> float:
    return statistics.quantiles(values, n=100, method="inclusive")[q - 1] if len(values) > 1 else values[0]


async def _reader(client: httpx.AsyncClient, job_id: int, stop_at: float, out) -> None:
    paths = ["/api/health", "/api/jobs", f"/api/jobs/{job_id}", f"/api/jobs/{job_id}/evaluations?after=-1",
             f"/api/jobs/{job_id}/best"]
    i = 0
    while time.monotonic() < stop_at:
        path = name = paths[i % len(paths)]
        if i % 7 == 6:  # now and then a whole trajectory, as a download or the view's rewatch
            best = (await client.get(f"/api/jobs/{job_id}/best")).json()
            path = f"/api/evaluations/{best['id']}/trajectory?format=json" if "id" in best else "/api/health"
            name = "/api/evaluations/{id}/trajectory" if "id" in best else path
        t0 = time.perf_counter()
        r = await client.get(path)
        out[("read", name.split("?")[0].replace(f"/{job_id}", "/{id}"))].append((time.perf_counter() - t0,
                                                                                 r.status_code))
        i += 1


async def _writer(client: httpx.AsyncClient, stop_at: float, out) -> None:
    while time.monotonic() < stop_at:
        t0 = time.perf_counter()
        r = await client.post("/api/jobs", json={"iterations": 3, "seed_points": 2})
        out[("write", "POST /api/jobs")].append((time.perf_counter() - t0, r.status_code))
        if r.status_code != 201:
            await asyncio.sleep(0.1)
            continue
        job = r.json()["id"]
        for method, path, body in (("PATCH", f"/api/jobs/{job}", {"iterations": 4}),
                                   ("POST", f"/api/jobs/{job}/pause", None),
                                   ("DELETE", f"/api/jobs/{job}", None)):
            t0 = time.perf_counter()
            r = await client.request(method, path, json=body)
            out[("write", f"{method} {path.replace(str(job), '{id}')}")].append((time.perf_counter() - t0,
                                                                                 r.status_code))


async def _load(url: str, job_id: int, seconds: float, readers: int, writers: int):
    out: dict[tuple[str, str], list[tuple[float, int]]] = defaultdict(list)
    stop_at = time.monotonic() + seconds
    limits = httpx.Limits(max_connections=readers + writers + 4)
    async with httpx.AsyncClient(base_url=url, timeout=60.0, limits=limits) as client:
        await asyncio.gather(*[_reader(client, job_id, stop_at, out) for _ in range(readers)],
                             *[_writer(client, stop_at, out) for _ in range(writers)])
    return out


def _one_client(args: tuple[str, int, float, bool]):
    """A client in a process of its own: its samples."""
    url, job_id, seconds, writer = args
    out: dict[tuple[str, str], list[tuple[float, int]]] = defaultdict(list)

    async def run():
        async with httpx.AsyncClient(base_url=url, timeout=60.0) as client:
            stop_at = time.monotonic() + seconds
            await (_writer(client, stop_at, out) if writer else _reader(client, job_id, stop_at, out))

    asyncio.run(run())
    return dict(out)


def _load_in_processes(url: str, job_id: int, seconds: float, readers: int, writers: int):
    from multiprocessing import Pool

    out: dict[tuple[str, str], list[tuple[float, int]]] = defaultdict(list)
    jobs = [(url, job_id, seconds, False)] * readers + [(url, job_id, seconds, True)] * writers
    with Pool(len(jobs)) as pool:
        for samples in pool.map(_one_client, jobs):
            for key, values in samples.items():
                out[key].extend(values)
    return out


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--seconds", type=float, default=120.0)
    parser.add_argument("--readers", type=int, default=26)
    parser.add_argument("--writers", type=int, default=4)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--processes", action="store_true")
    parser.add_argument("--db", help="start from a copy of this database")
    parser.add_argument("--read-job", type=int, help="the stored job the readers read (default: the running one)")
    args = parser.parse_args()
    folder = tempfile.mkdtemp(prefix="driftlab-load-")
    if args.db:
        shutil.copy(args.db, os.path.join(folder, "load.db"))
    with served(os.path.join(folder, "load.db"), "--workers", str(args.workers),
                log_file=os.path.join(folder, "serve.log")) as url:
        job = httpx.post(f"{url}/api/jobs", json={"iterations": 500, "name": "under-load"}).json()
        while httpx.get(f"{url}/api/jobs/{job['id']}").json()["n_done"] < 3:  # episodes in flight, warm
            time.sleep(0.5)
        read_job = args.read_job or job["id"]
        if args.processes:
            out = _load_in_processes(url, read_job, args.seconds, args.readers, args.writers)
        else:
            out = asyncio.run(_load(url, read_job, args.seconds, args.readers, args.writers))
        done = httpx.get(f"{url}/api/jobs/{job['id']}").json()["n_done"]
    total = sum(len(v) for v in out.values())
    print(f"{args.readers} readers, {args.writers} writers ({'processes' if args.processes else 'one event loop'}), "
          f"{args.seconds:g} s, {total / args.seconds:.0f} requests/s, job on {args.workers} workers "
          f"({done} evaluations done by the end)")
    reads = [s for (kind, _), v in out.items() if kind == "read" for s in v]
    for name, samples in [(("all", "reads"), reads)] + sorted(out.items()):
        times = [t for t, _ in samples]
        errors = sum(code >= 500 for _, code in samples)
        codes = sorted({code for _, code in samples})
        print(f"{name[0]:>5} {name[1]:<42} n {len(samples):6d}  5xx {errors:3d}  codes {codes}  "
              f"p50 {1e3 * statistics.median(times):7.1f} ms  p95 {1e3 * _percentile(times, 95):7.1f} ms  "
              f"p99 {1e3 * _percentile(times, 99):7.1f} ms")


if __name__ == "__main__":
    main()
