"""The REST API (thin routes over :mod:`driftlab.db.storage`) and the job worker's lifecycle."""

from __future__ import annotations

import csv
import io
import json
import os
import secrets
from contextlib import asynccontextmanager
from datetime import UTC
from typing import Any

from fastapi import Depends, FastAPI, Header, HTTPException, Query, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import HTMLResponse, JSONResponse, Response

from driftlab.core.errors import ConfigError
from driftlab.core.tuning import TuningSpec
from driftlab.db import storage
from driftlab.db.models import Evaluation, Job
from driftlab.server.schemas import JobCreate
from driftlab.server.view import RecordingCache, add_view_routes
from driftlab.server.worker import JobWorker
from driftlab.web.dashboard import Dashboard
from driftlab.worker.executor import LocalProcessExecutor

MAX_PAGE = 1000
LANDING_PAGE = """<!doctype html><html><head><meta charset="utf-8"><title>DriftLab</title>
<style>body{font:16px/1.5 system-ui,sans-serif;max-width:44em;margin:3em auto;padding:0 1em;color:#222}
a{color:#1c5fd1}code{background:#f2f2f2;padding:0 .3em}</style></head><body>
<h1>DriftLab</h1>
<p>Learning-based inertia drift: a car drifts a figure 8 under linear MPC while Bayesian optimization learns
where to flick and how to steer.</p>
<ul>
<li><a href="/viser/"><b>Open the 3D view</b></a>: the car driving the newest evaluation of a job, the convergence
plot, rewatching any episode, what-if sliders.</li>
<li><a href="/docs">REST API docs</a>: start, pause and resume tuning jobs; download trajectories.</li>
<li><a href="/api/jobs">Jobs (JSON)</a></li>
</ul>
<p>Start a job: <code>curl -X POST localhost:8000/api/jobs -H 'content-type: application/json'
-d '{"iterations": 100}'</code></p>
</body></html>"""


def _require_token(authorization: str | None = Header(default=None)) -> None:
    token = os.environ.get("DRIFTLAB_TOKEN")
    if token and not (authorization and secrets.compare_digest(authorization, f"Bearer {token}")):
        raise HTTPException(401, "this endpoint needs 'Authorization: Bearer <DRIFTLAB_TOKEN>'")


def _evaluation_dict(e: Evaluation) -> dict[str, Any]:
    return {"id": e.id, "job_id": e.job_id, "index": e.index, "theta": e.theta, "J": e.J, "status": e.status,
            "completed": e.completed, "metrics": e.metrics, "trigger_points": e.trigger_points,
            "wall_ms": e.wall_ms, "created_at": e.created_at.replace(tzinfo=UTC).isoformat()}


def _job_dict(session, job: Job) -> dict[str, Any]:
    n_done = storage.count_evaluations(session, job_id=job.id)
    iterations = job.spec["iterations"]
    best = storage.best_evaluation(session, job_id=job.id)
    rate = storage.seconds_per_evaluation(session, job_id=job.id) if job.status == "running" else None
    eta = None if rate is None else rate * (iterations - n_done)
    return {"id": job.id, "name": job.name, "status": job.status, "seed": job.seed, "n_done": n_done,
            "iterations": iterations, "progress": n_done / iterations, "eta_s": eta, "error": job.error,
            "best": None if best is None else {"evaluation_id": best.id, "index": best.index, "theta": best.theta,
                                               "J": best.J, "status": best.status},
            "spec": job.spec, "created_at": job.created_at.replace(tzinfo=UTC).isoformat()}


def _start_view(app: FastAPI, factory) -> None:
    """The 3D view and its what-if worker (a process of its own, so a what-if never waits behind a job)."""
    executor = LocalProcessExecutor(1)
    executor.warm_up()
    app.state.what_if_executor = executor
    app.state.dashboard = Dashboard(factory, run_episode=executor.submit)


def _stop_view(app: FastAPI) -> None:
    app.state.dashboard.stop()
    app.state.recordings.recorder.stop()
    app.state.what_if_executor.shutdown()


def create_app(db_url: str, *, workers: int = 2, start_worker: bool = True) -> FastAPI:
    factory = storage.open_database(db_url)
    worker = JobWorker(factory, workers=workers)

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        _start_view(app, factory)
        if start_worker:
            worker.start()
        yield
        if start_worker:
            worker.stop()
        _stop_view(app)

    app = FastAPI(title="DriftLab", version="0.1.0", lifespan=lifespan,
                  description="Learning-based inertia drift: tuning jobs, evaluations, trajectories.")
    app.state.factory = factory
    app.state.worker = worker
    app.state.recordings = RecordingCache(factory)
    add_view_routes(app, lambda: app.state.dashboard.port if hasattr(app.state, "dashboard") else None,
                    app.state.recordings,
                    lambda: len(app.state.dashboard.sessions) if hasattr(app.state, "dashboard") else 0)

    @app.exception_handler(RequestValidationError)
    async def _validation(_request: Request, exc: RequestValidationError):
        details = [{"field": ".".join(str(p) for p in err["loc"] if p != "body"), "message": err["msg"]}
                   for err in exc.errors()]
        summary = "; ".join(f"{d['field']}: {d['message']}" for d in details)
        return JSONResponse({"detail": summary, "errors": details}, status_code=422)

    @app.exception_handler(ConfigError)
    async def _config_error(_request: Request, exc: ConfigError):
        return JSONResponse({"detail": str(exc)}, status_code=422)

    @app.exception_handler(storage.NotFound)
    async def _not_found(_request: Request, exc: storage.NotFound):
        return JSONResponse({"detail": str(exc)}, status_code=404)

    @app.get("/", response_class=HTMLResponse, include_in_schema=False)
    def landing() -> str:
        return LANDING_PAGE

    @app.get("/api/health")
    def health() -> dict[str, str]:
        return {"status": "ok"}

    @app.post("/api/jobs", status_code=201, dependencies=[Depends(_require_token)])
    def create_job(body: JobCreate) -> dict[str, Any]:
        doc = body.model_dump(exclude_none=True, exclude={"name"})
        if "bounds" in doc:
            doc["bounds"] = {k: list(v) for k, v in doc["bounds"].items()}
        spec = TuningSpec.from_dict(doc)  # ConfigError -> 422 naming the field
        with storage.transaction(factory) as session:
            if body.name and storage.find_job(session, name=body.name) is not None:
                raise HTTPException(409, f"name: a job named {body.name!r} exists")
            name = body.name or storage.unique_job_name(session, "job")
            job = storage.create_job(session, name=name, spec=spec.to_dict(), seed=spec.seed)
            out = _job_dict(session, job)
        worker.wake()
        return out

    @app.get("/api/jobs")
    def list_jobs() -> list[dict[str, Any]]:
        with storage.transaction(factory) as session:
            return [_job_dict(session, j) for j in storage.list_jobs(session)]

    @app.get("/api/jobs/{job_id}")
    def get_job(job_id: int) -> dict[str, Any]:
        with storage.transaction(factory) as session:
            return _job_dict(session, storage.get_job(session, job_id=job_id))

    def _transition(job_id: int, allowed: tuple[str, ...], target: str) -> dict[str, Any]:
        with storage.transaction(factory) as session:
            job = storage.get_job(session, job_id=job_id)
            if job.status not in allowed:
                raise HTTPException(409, f"job {job_id} is {job.status}; this needs one of {', '.join(allowed)}")
            job.status = target
            out = _job_dict(session, job)
        worker.wake()
        return out

    @app.post("/api/jobs/{job_id}/pause", dependencies=[Depends(_require_token)])
    def pause(job_id: int) -> dict[str, Any]:
        return _transition(job_id, ("queued", "running"), "paused")

    @app.post("/api/jobs/{job_id}/resume", dependencies=[Depends(_require_token)])
    def resume(job_id: int) -> dict[str, Any]:
        return _transition(job_id, ("paused", "failed"), "queued")

    @app.get("/api/jobs/{job_id}/evaluations")
    def list_evaluations(job_id: int, after: int = Query(-1, ge=-1),
                         limit: int = Query(MAX_PAGE, ge=1, le=MAX_PAGE)) -> Response:
        """Evaluations with index > after, in order (poll with the last index you have)."""
        with storage.transaction(factory) as session:
            storage.get_job(session, job_id=job_id)
            rows = [_evaluation_dict(e) for e in storage.evaluations(session, job_id=job_id, after=after, limit=limit)]
        # Plain JSON types already: skip FastAPI's generic encoder, which dominates the cost at 500 rows.
        return Response(json.dumps(rows), media_type="application/json")

    @app.get("/api/jobs/{job_id}/best")
    def best(job_id: int) -> dict[str, Any]:
        with storage.transaction(factory) as session:
            storage.get_job(session, job_id=job_id)
            e = storage.best_evaluation(session, job_id=job_id)
            if e is None:
                raise HTTPException(404, f"job {job_id} has no evaluations yet")
            return _evaluation_dict(e)

    @app.get("/api/evaluations/{evaluation_id}")
    def get_evaluation(evaluation_id: int) -> dict[str, Any]:
        with storage.transaction(factory) as session:
            return _evaluation_dict(storage.get_evaluation(session, evaluation_id=evaluation_id))

    @app.get("/api/evaluations/{evaluation_id}/trajectory")
    def trajectory(evaluation_id: int, format: str = Query("csv", pattern="^(csv|json)$")) -> Response:  # noqa: A002
        with storage.transaction(factory) as session:
            columns, data = storage.trajectory_array(session, evaluation_id=evaluation_id)
        filename = f"evaluation-{evaluation_id}.{format}"
        headers = {"Content-Disposition": f'attachment; filename="{filename}"'}
        if format == "json":
            body = json.dumps({"columns": columns, "rows": data.tolist()})
            return Response(body, media_type="application/json", headers=headers)
        buffer = io.StringIO()
        writer = csv.writer(buffer)
        writer.writerow(columns)
        writer.writerows(data.tolist())
        return Response(buffer.getvalue(), media_type="text/csv", headers=headers)

    return app
