"""How long `driftlab serve` takes to exit on SIGTERM (what `docker stop` sends, killing 10 s later) while a job, a
rescore and a calibration run: the median and the max of N stops, each of a fresh server on a fresh database, and
whether the database file was left without its write-ahead log.

Run: python benchmarks/bench_stop.py [N]   (default 10; the machine's load is printed beside the figures)
"""

import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from tests.server_process import free_port, start_server, wait_for, wait_status  # noqa: E402


def one_stop() -> tuple[float, bool]:
    folder = Path(tempfile.mkdtemp())
    proc, url = start_server(folder / "driftlab.db", free_port(), extra_args=("--workers", "2"))
    http = httpx.Client(timeout=60)  # a loaded machine answers the first requests slowly
    try:
        tuned = http.post(f"{url}/api/jobs", json={"iterations": 1, "robust_samples": 1,
                                                    "confirm_samples": 0}).json()["id"]
        wait_status(url, tuned, {"finished"}, timeout_s=300)
        job = http.post(f"{url}/api/jobs", json={"iterations": 400}).json()["id"]
        http.post(f"{url}/api/jobs/{tuned}/rescore", json={"samples": 60})
        calibration = http.post(f"{url}/api/calibrations", json={"plant": "commonroad_std", "points": "0.5@44",
                                                                  "iterations": 40, "seeds": 2}).json()["id"]
        wait_for(f"{url}/api/jobs/{job}", lambda j: j["n_done"] >= 2, timeout_s=300)
        wait_for(f"{url}/api/calibrations/{calibration}", lambda c: c["status"] == "running", timeout_s=300)
        started = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=120)
        return time.monotonic() - started, not (folder / "driftlab.db-wal").exists()
    finally:
        http.close()
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 10
    stops = [one_stop() for _ in range(n)]
    seconds = [s for s, _ in stops]
    cores = subprocess.run(["nproc"], capture_output=True, text=True).stdout.strip()
    print(f"{n} stops with a job, a rescore and a calibration running: exit median {statistics.median(seconds):.2f} "
          f"s, max {max(seconds):.2f} s; no WAL left in {sum(clean for _, clean in stops)}/{n}; "
          f"load average {os.getloadavg()[0]:.1f}; {cores} cores")


if __name__ == "__main__":
    main()
