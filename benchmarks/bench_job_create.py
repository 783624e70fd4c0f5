"""How long POST /api/jobs takes, on a real server: the default plant, and CommonRoad's BMW at drifts the server has
not seen before (each a new sideslip or radius, so nothing is cached), where the controller's model is fitted to
the car's drift. Then how long until the runner has fitted each of those jobs and stored it fitted (its
``spec.config`` carries ``vehicle``). Prints medians.

Run: OMP_NUM_THREADS=1 python benchmarks/bench_job_create.py [--drifts 8]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time

import httpx
from served import served


def _post(url: str, config: dict) -> tuple[float, dict]:
    started = time.perf_counter()
    r = httpx.post(f"{url}/api/jobs", json={"iterations": 1, "seed_points": 1, "robust_samples": 1,
                                            "confirm_samples": 0, "config": config}, timeout=60)
    assert r.status_code == 201, r.text
    return time.perf_counter() - started, r.json()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drifts", type=int, default=8)
    args = parser.parse_args()
    drifts = [(round(0.46 + 0.01 * i, 2), 44.0 - 2.0 * (i % 3)) for i in range(args.drifts)]
    with tempfile.TemporaryDirectory() as folder, served(f"{folder}/create.db") as url:
        _post(url, {})  # the first request imports what the rest use
        default = [_post(url, {})[0] for _ in range(args.drifts)]
        car, ids = [], []
        for sideslip_rad, radius_m in drifts:
            took, job = _post(url, {"plant.model": "commonroad_std", "scenario.sideslip_rad": sideslip_rad,
                                    "scenario.left_radius_m": radius_m, "scenario.right_radius_m": radius_m})
            car.append(took)
            ids.append((job["id"], time.perf_counter(), "vehicle" in job["spec"]["config"]))
        fitted_after = []
        for job_id, posted, _ in ids:
            while "vehicle" not in httpx.get(f"{url}/api/jobs/{job_id}").json()["spec"]["config"]:
                time.sleep(0.05)
            fitted_after.append(time.perf_counter() - posted)
    print(f"POST /api/jobs, default plant: median {1e3 * statistics.median(default):.0f} ms ({args.drifts} jobs)")
    print(f"POST /api/jobs, CommonRoad BMW at a new drift: median {1e3 * statistics.median(car):.0f} ms, max "
          f"{1e3 * max(car):.0f} ms ({args.drifts} drifts, {', '.join(f'{b:g}@{r:g}' for b, r in drifts)}); "
          f"fitted in the POST: {sum(f for _, _, f in ids)} of {len(ids)}")
    print(f"  stored fitted by the runner: median {statistics.median(fitted_after):.2f} s after its POST")


if __name__ == "__main__":
    main()
