"""DriftLab's settings from the environment (``DRIFTLAB_*``), one class for the CLI and the server.

The database: ``--db FILE`` wins, then ``DRIFTLAB_DATABASE_URL``, then the one default file that `serve`,
`tune`, `rescore` and `report` share wherever they are started: ``$XDG_DATA_HOME/driftlab/driftlab.db``
(``~/.local/share/driftlab/driftlab.db``).
"""

from __future__ import annotations

import os
from pathlib import Path

from pydantic import Field
from pydantic_settings import BaseSettings, SettingsConfigDict

MAX_TRAJECTORIES_PER_JOB = 5000
WHAT_IF_PER_MINUTE = 60.0


class Settings(BaseSettings):
    """Attributes:
        database_url: SQLAlchemy URL of the database (DRIFTLAB_DATABASE_URL).
        token: bearer token every API request must carry, if set (DRIFTLAB_TOKEN); /api/health, the pages and
            the OpenAPI document stay open.
        public_reads: with a token set, API reads (GET) need none (DRIFTLAB_PUBLIC_READS=1): a lab that shows its
            results to anyone on its network and lets only token holders change them.
        dask_address: a Dask scheduler (tcp://HOST:8786) to run episodes on (DRIFTLAB_DASK_ADDRESS); unset: a
            local process pool.
        allowed_hosts: host names this server answers to besides 127.0.0.1, localhost and ::1, comma-separated
            (DRIFTLAB_ALLOWED_HOSTS, e.g. "lab-pc.example.org,10.0.0.5"; "*" for any, behind a proxy that checks).
        max_body_bytes: the largest request body accepted (DRIFTLAB_MAX_BODY_BYTES, default 1 MB).
        max_episodes_per_job, max_episodes_per_study, max_queued_jobs: what one request may queue (see
            driftlab.server.quotas); the defaults allow the paper's runs many times over (a 500-run of the job
            default is 4000 episodes).
        max_trajectories_per_job: trajectories (each up to ~100 kB) a job keeps beyond its bests
            (DRIFTLAB_MAX_TRAJECTORIES_PER_JOB, default 5000, ~0.5 GB); later evaluations are stored without one,
            and an episode re-runs bit for bit from its theta, config and seed.
        what_if_per_minute: what-if episodes one browser tab may start a minute (DRIFTLAB_WHAT_IF_PER_MINUTE,
            default 60, bursts of 5): one open tab cannot keep the what-if worker busy for everyone.
        max_heavy_reads: search spaces, recordings and replays served at once (DRIFTLAB_MAX_HEAVY_READS, default 2:
            the server's cores); one more waits up to 5 s for a slot, then is a 503 with Retry-After.
        max_view_tabs: browser tabs of the 3D view at once (DRIFTLAB_MAX_VIEW_TABS, default 20); one more is
            closed with "try again later" (each streams a car at 30 Hz from the server process).
        header_timeout_s, body_timeout_s: how long a request's headers may take to arrive, and a request body may
            pause between chunks (DRIFTLAB_HEADER_TIMEOUT_S, default 10; DRIFTLAB_BODY_TIMEOUT_S, default 30;
            driftlab.server.slow_clients).
        request_threads: threads that run the API's request handlers at once (DRIFTLAB_REQUEST_THREADS, default 8;
            FastAPI's own default is 40): the handlers share one interpreter, and 40 threads taking turns at it
            served no more requests than 8, only in a less fair order (the longest waits grew).
        optimizer_process: each running job's optimizer (ask and tell) in a process of its own beside the server
            (DRIFTLAB_OPTIMIZER_PROCESS=1; default off: each on its job's thread; up to 8 processes started with
            the runner, each ~220 MB resident). Measured both ways in docs/benchmarks.md: with one job and 30 API
            clients on 2 cores, on: 80 requests/s and 145 evaluations of the job in 90 s (off: 65-73 and 88-111);
            with an 8-job study on a simulated 16-worker cluster, on: 148 evaluations/s (the workers 83 % busy) against
            122 off. Off by default because a local 2-core server gains little and starts each process's imports
            (~1 s of a core); compose.yaml (a cluster) sets it.
        max_rescore_episodes: episodes that queued and running rescores may wait for, all jobs together
            (DRIFTLAB_MAX_RESCORE_EPISODES, default 5000): rescores share the job runner's workers.
    """

    model_config = SettingsConfigDict(env_prefix="DRIFTLAB_", extra="ignore")

    database_url: str | None = None
    token: str | None = None
    public_reads: bool = False
    dask_address: str | None = None
    allowed_hosts: str = ""
    max_body_bytes: int = 1_000_000
    max_episodes_per_job: int = 100_000
    max_episodes_per_study: int = 1_000_000
    max_queued_jobs: int = 100
    max_trajectories_per_job: int = Field(default=MAX_TRAJECTORIES_PER_JOB, ge=1)
    what_if_per_minute: float = Field(default=WHAT_IF_PER_MINUTE, gt=0.0, le=6000.0)
    max_rescore_episodes: int = Field(default=5000, ge=1)
    max_heavy_reads: int = Field(default=2, ge=1, le=64)
    max_view_tabs: int = Field(default=20, ge=1, le=1000)
    header_timeout_s: float = Field(default=10.0, gt=0.0, le=3600.0)
    body_timeout_s: float = Field(default=30.0, gt=0.0, le=3600.0)
    request_threads: int = Field(default=8, ge=2, le=256)
    optimizer_process: bool = False

    def allowed_host_names(self) -> frozenset[str]:
        return frozenset(h.strip() for h in self.allowed_hosts.split(",") if h.strip())


def default_database_file() -> Path:
    data_home = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
    return Path(data_home) / "driftlab" / "driftlab.db"


def database_url(db: str | None, settings: Settings) -> str:
    """--db FILE (or URL), then DRIFTLAB_DATABASE_URL, then the shared default file (its folder created)."""
    if db:
        return db if "://" in db else f"sqlite:///{os.path.abspath(db)}"
    if settings.database_url:
        return settings.database_url
    path = default_database_file()
    path.parent.mkdir(parents=True, exist_ok=True)
    return f"sqlite:///{path}"
