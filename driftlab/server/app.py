"""The FastAPI app: routers (driftlab.server.routes), error handlers, and the lifespan of the job runner and the
3D view."""

from __future__ import annotations

import gc
from contextlib import asynccontextmanager

import anyio.to_thread
from fastapi import FastAPI, Request
from fastapi.exception_handlers import http_exception_handler
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from sqlalchemy.exc import OperationalError
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import Match

from driftlab.core.errors import ConfigError
from driftlab.db import lifecycle, storage
from driftlab.server.docs_page import add_docs_page
from driftlab.server.drift_check import DriftCheck
from driftlab.server.edge import EdgeGuard
from driftlab.server.evaluation_pages import EvaluationPages
from driftlab.server.heavy_reads import HeavyReads
from driftlab.server.openapi import document_edge
from driftlab.server.routes import analysis, calibrations, evaluations, jobs, pages, studies
from driftlab.server.security_headers import SecurityHeaders
from driftlab.server.trajectory_documents import TrajectoryDocuments
from driftlab.server.view import RecordingCache, add_view_routes
from driftlab.services.search_space import SearchSpaceCache
from driftlab.settings import Settings
from driftlab.web.view_app import ViewApp
from driftlab.worker.executors import LocalProcessExecutor
from driftlab.worker.job_runner import JobRunner


def _start_view(app: FastAPI, factory, settings: Settings) -> None:
    """The 3D view and its what-if worker (a process of its own, so a what-if never waits behind a job)."""
    executor = LocalProcessExecutor(1)
    executor.warm_up()
    app.state.what_if_executor = executor
    app.state.view_app = ViewApp(factory, run_episode=executor.submit,
                                 what_if_per_minute=settings.what_if_per_minute)


def _stop_view(app: FastAPI) -> None:
    app.state.view_app.stop()
    app.state.recordings.recorder.stop()
    app.state.what_if_executor.shutdown()


def _field(err: dict) -> str:
    """The request field an error is about: dotted, without the 'body' prefix; the body itself for bad JSON."""
    if err.get("type") == "json_invalid" or (len(err["loc"]) == 2 and isinstance(err["loc"][1], int)):
        return "body"
    return ".".join(str(p) for p in err["loc"] if p != "body") or "body"


METHODS = ("GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS")


def _allowed_methods(request: Request) -> str:
    """Every method a route serves at the request's path: Starlette's 405 names the first matching route's
    only, and FastAPI makes a route per method (GET and DELETE /api/jobs/{job_id} are two). Asked of the routes
    one method at a time, as routing would: FastAPI nests the routes of included routers."""
    routes = request.app.router.routes
    allowed = [method for method in METHODS
               if any(route.matches({**request.scope, "method": method})[0] == Match.FULL for route in routes)]
    return ", ".join(allowed)


def create_app(db_url: str, *, workers: int | None = 2, start_worker: bool = True, start_view: bool = True,
               settings: Settings | None = None) -> FastAPI:
    """The app; ``start_worker=False, start_view=False`` starts no process and no thread (in-process tests)."""
    settings = settings or Settings()
    factory = storage.open_database(db_url)
    runner = JobRunner(factory, workers=workers, dask_address=settings.dask_address,
                       max_trajectories_per_job=settings.max_trajectories_per_job,
                       optimizer_process=settings.optimizer_process)

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        anyio.to_thread.current_default_thread_limiter().total_tokens = settings.request_threads
        if start_view:
            _start_view(app, factory, settings)
        if start_worker:
            app.state.drift_check.warm_in_background()
            runner.start()
        # What startup made (modules, compiled kernels, the view's scene) lives as long as the server: out of the
        # collector's sight, a full collection no longer walks it (it stopped every request for ~270 ms).
        gc.freeze()
        yield
        if start_worker:
            runner.stop()
        if start_view:
            _stop_view(app)
        storage.close_database(factory)

    app = FastAPI(title="DriftLab", version="0.1.0", lifespan=lifespan, docs_url=None, redoc_url=None,
                  description="Learning-based inertia drift: tuning jobs, evaluations, trajectories.")
    app.state.settings = settings
    app.state.drift_check = DriftCheck()
    # Outermost: hosts, origins, the token and the body size are checked before anything else runs.
    app.add_middleware(EdgeGuard, token=settings.token, allowed_hosts=settings.allowed_host_names(),
                       max_body_bytes=settings.max_body_bytes, public_reads=settings.public_reads,
                       body_timeout_s=settings.body_timeout_s)
    app.add_middleware(SecurityHeaders)  # outside the edge: its refusals carry the headers too
    app.state.factory = factory
    app.state.evaluation_pages = EvaluationPages()
    app.state.trajectory_documents = TrajectoryDocuments()
    app.state.runner = runner
    app.state.recordings = RecordingCache(factory)
    app.state.search_spaces = SearchSpaceCache()
    app.state.heavy_reads = HeavyReads(settings.max_heavy_reads)
    add_docs_page(app)
    app.include_router(pages.router)
    pages.mount_static(app)
    app.include_router(jobs.router)
    app.include_router(analysis.router)
    app.include_router(evaluations.router)
    app.include_router(studies.router)
    app.include_router(calibrations.router)
    add_view_routes(app, lambda: app.state.view_app.port if hasattr(app.state, "view_app") else None,
                    app.state.recordings,
                    lambda: len(app.state.view_app.sessions) if hasattr(app.state, "view_app") else 0,
                    max_tabs=settings.max_view_tabs)
    document_edge(app, token_set=bool(settings.token), public_reads=settings.public_reads)

    @app.exception_handler(RequestValidationError)
    async def _validation(_request: Request, exc: RequestValidationError):
        details = [{"field": _field(err), "message": err["msg"]} for err in exc.errors()]
        summary = "; ".join(f"{d['field']}: {d['message']}" for d in details)
        return JSONResponse({"detail": summary, "errors": details}, status_code=422)

    @app.exception_handler(ConfigError)
    async def _config_error(_request: Request, exc: ConfigError):
        # The same shape as a schema error: ConfigError messages start with the field they are about.
        message = str(exc)
        field = exc.field or message.split(" ", 1)[0].strip("'\":")
        return JSONResponse({"detail": message, "errors": [{"field": field, "message": message}]}, status_code=422)

    @app.exception_handler(lifecycle.TransitionError)
    async def _conflict(_request: Request, exc: lifecycle.TransitionError):
        # Not in a status that allows it (pause a finished job, delete a running one): the resource is unchanged.
        return JSONResponse({"detail": str(exc)}, status_code=409)

    @app.exception_handler(storage.NotFound)
    async def _not_found(_request: Request, exc: storage.NotFound):
        return JSONResponse({"detail": str(exc)}, status_code=404)

    @app.exception_handler(StarletteHTTPException)
    async def _http_error(request: Request, exc: StarletteHTTPException):
        if exc.status_code == 400 and exc.detail == "There was an error parsing the body":
            # FastAPI's answer to a body it cannot decode (not UTF-8): a malformed request body like any other.
            message = "body: not a UTF-8 JSON document"
            return JSONResponse({"detail": message, "errors": [{"field": "body", "message": message}]},
                                status_code=422)
        if exc.status_code == 405:
            return JSONResponse({"detail": exc.detail}, status_code=405, headers={"Allow": _allowed_methods(request)})
        return await http_exception_handler(request, exc)

    @app.exception_handler(OperationalError)
    async def _storage_unavailable(_request: Request, exc: OperationalError):
        # A read-only file, a full disk, a lock held past the timeout: nothing was changed; try again or fix it.
        reason = str(exc.orig or exc).splitlines()[0]
        return JSONResponse({"detail": f"storage: {reason}"}, status_code=503)

    @app.exception_handler(Exception)
    async def _internal(_request: Request, exc: Exception):
        return JSONResponse({"detail": f"internal error ({type(exc).__name__}); the server log has the trace"},
                            status_code=500)

    return app
