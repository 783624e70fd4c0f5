"""Reads that used to stall the server, against a real `driftlab serve` (issue: a service you can put on a lab
network). Prints, for each scenario, the health check's p50/p99 latency (polled at 5 Hz by its own client while
the scenario runs), the answers the load got (200 / 503 ...) and the server's RSS before, at its peak and after.

1. 45 clients for 45 s on the search space (x, y varied) and the recordings of a stored 500-evaluation job;
2. 50 browser-tab websockets on the 3D view (through the /viser relay) for 30 s;
3. 600 requests without the token that announce a 0.9 MB body (under the 1 MB limit) and send 10 bytes of it,
   held open (token server); counts how many the server closed within 60 s.

Run: python benchmarks/bench_heavy_reads.py [--db JOB500.db --job ID]
Without --db it first tunes a 500-evaluation job of the default plant (`driftlab tune --iterations 500`, minutes).
"""

from __future__ import annotations

import argparse
import asyncio
import os
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path

import httpx
import psutil
import viser
from websockets.asyncio.client import connect

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tests.server_process import free_port, start_server  # noqa: E402

TOKEN = "bench-token"
PAIRS = [("c_lr", "c_rl"), ("c_lr", "k"), ("dV", "k"), ("c_rl", "dV"), (None, None)]


class Watch:
    """The health check's latency at 5 Hz and the server's RSS while a scenario runs."""

    def __init__(self, url: str, pid: int) -> None:
        self.url, self.process = url, psutil.Process(pid)
        self.latencies: list[float] = []
        self.rss_mb = [self._rss()]
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _rss(self) -> float:
        return self.process.memory_info().rss / 2**20

    def _run(self) -> None:
        with httpx.Client(timeout=60) as client:
            while not self._stop.is_set():
                t0 = time.perf_counter()
                try:
                    client.get(f"{self.url}/api/health", headers={"authorization": f"Bearer {TOKEN}"})
                    self.latencies.append(time.perf_counter() - t0)
                except httpx.HTTPError:
                    self.latencies.append(float("inf"))
                self.rss_mb.append(self._rss())
                self._stop.wait(max(0.0, 0.2 - (time.perf_counter() - t0)))

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()
        time.sleep(2.0)
        self.rss_mb.append(self._rss())

    def line(self) -> str:
        q = statistics.quantiles(self.latencies, n=100, method="inclusive")
        return (f"health p50 {q[49] * 1e3:.0f} ms, p99 {q[98] * 1e3:.0f} ms ({len(self.latencies)} checks); RSS "
                f"{self.rss_mb[0]:.0f} MB before, {max(self.rss_mb):.0f} peak, {self.rss_mb[-1]:.0f} after")


async def _heavy_client(url: str, job_id: int, evaluation_ids: list[int], i: int, stop_at: float, out: Counter):
    async with httpx.AsyncClient(timeout=120, headers={"authorization": f"Bearer {TOKEN}"}) as client:
        k = i
        while time.monotonic() < stop_at:
            if k % 2:
                x, y = PAIRS[k % len(PAIRS)]
                params = {"x": x, "y": y} if x else {}
                r = await client.get(f"{url}/api/jobs/{job_id}/search-space", params=params)
                out[("search-space", r.status_code)] += 1
            else:
                kind = "recording.viser" if k % 4 else "replay.html"
                r = await client.get(f"{url}/api/evaluations/{evaluation_ids[k % len(evaluation_ids)]}/{kind}")
                out[(kind, r.status_code)] += 1
            if r.status_code == 503:
                await asyncio.sleep(float(r.headers.get("retry-after", "1")))
            k += 1


async def _tab(url: str, stop_at: float, out: Counter) -> None:
    subprotocol = f"viser-v{viser.__version__}"
    try:
        async with connect(url.replace("http", "ws") + "/viser", subprotocols=[subprotocol], origin=url,
                           additional_headers={"cookie": f"driftlab_token={TOKEN}"}, max_size=None) as ws:
            while time.monotonic() < stop_at:
                await asyncio.wait_for(ws.recv(), timeout=max(0.1, stop_at - time.monotonic()))
            out["streamed to the end"] += 1
    except TimeoutError:
        out["streamed to the end"] += 1
    except Exception as exc:  # noqa: BLE001 (a refused or closed tab is what is counted)
        code = getattr(getattr(exc, "rcvd", None), "code", None)
        out[f"closed ({code})" if code else type(exc).__name__] += 1


def _held_bodies(url: str, n: int, wait_s: float) -> tuple[int, int]:
    """(opened, closed by the server within wait_s) of n connections holding a 0.9 MB body after 10 bytes."""
    host, port = url.removeprefix("http://").split(":")
    sockets = []
    for _ in range(n):
        s = socket.create_connection((host, int(port)))
        s.sendall(f"POST /api/jobs HTTP/1.1\r\nHost: {host}:{port}\r\ncontent-type: application/json\r\n"
                  f"content-length: 900000\r\n\r\n{{\"name\": ".encode())
        s.setblocking(False)
        sockets.append(s)
    deadline, closed = time.monotonic() + wait_s, set()
    while time.monotonic() < deadline and len(closed) < n:
        for i, s in enumerate(sockets):
            if i in closed:
                continue
            try:
                while s.recv(65536):
                    pass
                closed.add(i)  # b"": the server closed it
            except BlockingIOError:
                pass
            except OSError:
                closed.add(i)
        time.sleep(0.5)
    for s in sockets:
        s.close()
    return n, len(closed)


def _job_500(db: Path) -> int:
    started = time.monotonic()
    subprocess.run([sys.executable, "-m", "driftlab.cli", "tune", "--iterations", "500", "--db", str(db), "--name",
                    "job500"], check=True, capture_output=True, env={**os.environ, "OMP_NUM_THREADS": "1"})
    print(f"tuned a 500-evaluation job in {time.monotonic() - started:.0f} s")
    return 1


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--db")
    parser.add_argument("--job", type=int, default=1)
    parser.add_argument("--seconds", type=float, default=45.0)
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp())
    db = work / "bench.db"
    if args.db:
        shutil.copy(args.db, db)
        job_id = args.job
    else:
        job_id = _job_500(db)
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f}")
    proc, url = start_server(db, free_port(), env_extra={"DRIFTLAB_TOKEN": TOKEN})
    try:
        auth = {"authorization": f"Bearer {TOKEN}"}
        evaluations = httpx.get(f"{url}/api/jobs/{job_id}/evaluations?after=-1&limit=1000", headers=auth,
                                timeout=60).json()
        ids = [e["id"] for e in evaluations if e.get("status") == "completed"][:40] or [evaluations[0]["id"]]
        print(f"job {job_id}: {len(evaluations)} evaluations")

        async def heavy():
            out: Counter = Counter()
            stop_at = time.monotonic() + args.seconds
            await asyncio.gather(*(_heavy_client(url, job_id, ids, i, stop_at, out) for i in range(45)))
            return out

        with Watch(url, proc.pid) as watch:
            answers = asyncio.run(heavy())
        print(f"1. 45 clients on search spaces and recordings, {args.seconds:.0f} s: {watch.line()}")
        print("   answers: " + ", ".join(f"{k} {s}: {n}" for (k, s), n in sorted(answers.items())))

        async def tabs():
            out: Counter = Counter()
            stop_at = time.monotonic() + 30
            await asyncio.gather(*(_tab(url, stop_at, out) for _ in range(50)))
            return out

        with Watch(url, proc.pid) as watch:
            outcome = asyncio.run(tabs())
        print(f"2. 50 view tabs, 30 s: {watch.line()}")
        print("   tabs: " + ", ".join(f"{k}: {n}" for k, n in sorted(outcome.items())))

        with Watch(url, proc.pid) as watch:
            opened, closed = _held_bodies(url, 600, 60.0)
        print(f"3. {opened} held 0.9 MB bodies without the token: {closed} closed by the server within 60 s; "
              f"{watch.line()}")
    finally:
        proc.terminate()
        proc.wait(timeout=60)


if __name__ == "__main__":
    main()
