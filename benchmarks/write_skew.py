"""Write skew on a job's budget, against a real server: 6 clients keep PATCHing a fast-failing job's budget down
to what it has done (and now and then back up) while its runner stores evaluations. Nothing may be stored past
the budget: at every read and at the end, n_done <= iterations.

Run: python benchmarks/write_skew.py [--seconds 60] [--clients 6]
"""

from __future__ import annotations

import argparse
import os
import random
import tempfile
import threading
import time

import httpx
from served import served


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--clients", type=int, default=6)
    args = parser.parse_args()
    folder = tempfile.mkdtemp(prefix="driftlab-skew-")
    seen: list[tuple[int, int]] = []
    codes: dict[int, int] = {}
    lock = threading.Lock()
    with served(os.path.join(folder, "skew.db")) as url:
        # Spins out within ~2 s of simulated time: evaluations come fast, so the race has many chances.
        job = httpx.post(f"{url}/api/jobs", json={"iterations": 5000, "robust_samples": 1, "confirm_samples": 0,
                                                  "config": {"plant.friction_scale": 0.8}}).json()
        stop_at = time.monotonic() + args.seconds

        def client(seed: int) -> None:
            rng = random.Random(seed)
            with httpx.Client(base_url=url, timeout=60) as http:
                while time.monotonic() < stop_at:
                    body = http.get(f"/api/jobs/{job['id']}").json()
                    with lock:
                        seen.append((body["n_done"], body["iterations"]))
                    target = body["n_done"] + (rng.randint(1, 5) if rng.random() < 0.3 else 0)
                    r = http.patch(f"/api/jobs/{job['id']}", json={"iterations": max(target, 1)})
                    with lock:
                        codes[r.status_code] = codes.get(r.status_code, 0) + 1
                    if body["status"] in ("finished", "paused"):
                        http.post(f"/api/jobs/{job['id']}/resume")

        threads = [threading.Thread(target=client, args=(i,)) for i in range(args.clients)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        time.sleep(2.0)  # the runner's last evaluation lands or is refused
        final = httpx.get(f"{url}/api/jobs/{job['id']}").json()
        stored = len(httpx.get(f"{url}/api/jobs/{job['id']}/evaluations").json())
    over = [s for s in seen if s[0] > s[1]]
    print(f"{args.clients} clients, {args.seconds:g} s: {len(seen)} reads, "
          f"PATCH statuses {dict(sorted(codes.items()))}")
    print(f"reads with n_done > iterations: {len(over)}; final: n_done {final['n_done']}, stored {stored}, "
          f"iterations {final['iterations']}, status {final['status']}")
    print("OK: never past the budget" if not over and stored <= final["iterations"] else "FAILED: past the budget")


if __name__ == "__main__":
    main()
