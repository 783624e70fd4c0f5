"""A real `driftlab serve` for the HTTP benchmarks: started on a free port, answered health, stopped after."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager

import httpx


@contextmanager
def served(db_file: str, *extra_args: str, log_file: str | None = None) -> Iterator[str]:
    """The server's base URL while the block runs (its episode workers at one BLAS thread each)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    log = open(log_file, "w") if log_file else subprocess.DEVNULL
    proc = subprocess.Popen([sys.executable, "-m", "driftlab.cli", "serve", "--port", str(port), "--db", db_file,
                             *extra_args], env={**os.environ, "OMP_NUM_THREADS": "1"}, stdout=subprocess.DEVNULL,
                            stderr=log)
    url = f"http://127.0.0.1:{port}"
    try:
        for _ in range(600):
            try:
                httpx.get(f"{url}/api/health", timeout=1)
                break
            except httpx.HTTPError:
                time.sleep(0.1)
        yield url
    finally:
        proc.terminate()
        proc.wait(timeout=60)
        if log_file:
            log.close()
