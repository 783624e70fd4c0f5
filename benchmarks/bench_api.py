"""Requests per second and p95 latency of GET /api/jobs/{id}/evaluations on a stored job.

Run: python benchmarks/bench_api.py DB_FILE [JOB_ID]   (e.g. the database of a 500-iteration `driftlab tune`)
"""

import statistics
import sys
import time
from concurrent.futures import ThreadPoolExecutor

import httpx
from served import served


def main() -> None:
    db, job_id = sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 1
    with served(db) as url:
        n_evals = len(httpx.get(f"{url}/api/jobs/{job_id}/evaluations").json())

        def one(_):
            with httpx.Client() as client:
                t0 = time.perf_counter()
                r = client.get(f"{url}/api/jobs/{job_id}/evaluations")
                return time.perf_counter() - t0, r.status_code

        for concurrency in (1, 4):
            runs = []
            for _ in range(3):
                t0 = time.perf_counter()
                with ThreadPoolExecutor(concurrency) as pool:
                    results = list(pool.map(one, range(60)))
                wall = time.perf_counter() - t0
                latencies = sorted(r[0] for r in results)
                assert all(r[1] == 200 for r in results)
                runs.append((60 / wall, latencies[int(0.95 * len(latencies)) - 1]))
            print(f"{n_evals} evaluations, {concurrency} concurrent clients: "
                  f"{statistics.median(r[0] for r in runs):.1f} req/s, "
                  f"p95 {1e3 * statistics.median(r[1] for r in runs):.0f} ms (median of 3 x 60 requests)")


if __name__ == "__main__":
    main()
