"""Enqueue under a burst: 60 requests of 100 thetas on a paused 5000-evaluation job of a served DriftLab; prints
how many were accepted, how the rest were refused, and the latency's median, p99 and maximum.

Run: driftlab serve --db sqlite:////tmp/enqueue.db --port 8000 --workers 1 &
     python benchmarks/bench_enqueue.py [--url http://127.0.0.1:8000] [--requests 60]
"""

from __future__ import annotations

import argparse
import time

import httpx
import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--url", default="http://127.0.0.1:8000")
    parser.add_argument("--requests", type=int, default=60)
    args = parser.parse_args()
    with httpx.Client(base_url=args.url, timeout=30) as client:
        job = client.post("/api/jobs", json={"iterations": 5000}).json()
        client.post(f"/api/jobs/{job['id']}/pause")
        latencies, statuses = [], []
        for r in range(args.requests):
            body = {"thetas": [{"k": 0.001 * n, "dV": 0.001 * r} for n in range(100)]}
            started = time.perf_counter()
            answer = client.post(f"/api/jobs/{job['id']}/enqueue", json=body)
            latencies.append(time.perf_counter() - started)
            statuses.append(answer.status_code)
        print(f"{statuses.count(202)} accepted, refused: {sorted(set(s for s in statuses if s != 202))}; last: "
              f"{answer.text[:160]}")
        print(f"latency median {np.median(latencies) * 1000:.1f} ms, p99 {np.quantile(latencies, 0.99) * 1000:.1f} ms, "
              f"max {max(latencies) * 1000:.1f} ms")


if __name__ == "__main__":
    main()
