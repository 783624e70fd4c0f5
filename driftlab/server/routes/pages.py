"""The landing page, the dashboard page (jobs and their search space, driftlab/server/static) and the health
check."""

from __future__ import annotations

import html
from pathlib import Path

from fastapi import APIRouter, FastAPI, Request
from fastapi.responses import FileResponse, HTMLResponse, RedirectResponse, Response
from fastapi.staticfiles import StaticFiles

from driftlab.server.responses import Health
from driftlab.server.token_cookie import token_to_cookie

router = APIRouter()
STATIC = Path(__file__).resolve().parent.parent / "static"

LANDING_PAGE = """<!doctype html><html><head><meta charset="utf-8"><title>DriftLab</title>
<style>body{font:16px/1.5 system-ui,sans-serif;max-width:44em;margin:3em auto;padding:0 1em;color:#222}
a{color:#1c5fd1}code{background:#f2f2f2;padding:0 .3em}</style></head><body>
<h1>DriftLab</h1>
<p>Learning-based inertia drift: a car drifts a figure 8 under linear MPC while Bayesian optimization learns
where to flick and how to steer.</p>
<ul>
<li><a href="/viser/"><b>Open the 3D view</b></a>: the car driving the newest evaluation of a job, the convergence
plot, rewatching any episode, what-if sliders.</li>
<li><a href="/dashboard/"><b>Open the dashboard</b></a>: start, pause, resume, extend, clone, delete and rescore
jobs; each job's convergence and search space (slices, parallel coordinates, the GP's mean, uncertainty and
failure probability, parameter importance).</li>
<li><a href="/docs">REST API docs</a>: start, pause and resume tuning jobs; download trajectories.</li>
<li><a href="/api/jobs">Jobs (JSON)</a></li>
</ul>
<p>Start a job: <code>curl -X POST {base}/api/jobs -H 'content-type: application/json'
-d '{"iterations": 100}'</code></p>
</body></html>"""


@router.get("/", response_class=HTMLResponse, include_in_schema=False)
def landing(request: Request) -> str:
    # The address this page was reached at (the edge has checked the Host header): the example works as shown.
    base = f"{request.url.scheme}://{request.headers.get('host', '127.0.0.1:8000')}"
    return LANDING_PAGE.replace("{base}", html.escape(base))


@router.get("/dashboard", include_in_schema=False)
def dashboard_redirect(request: Request) -> RedirectResponse:
    query = f"?{request.url.query}" if request.url.query else ""
    return RedirectResponse(f"/dashboard/{query}")


@router.get("/dashboard/", include_in_schema=False)
def dashboard(request: Request) -> Response:
    given = request.query_params.get("token")
    if given is not None:
        return token_to_cookie(request, given)
    return FileResponse(STATIC / "dashboard.html", media_type="text/html")


@router.get("/api/health", tags=["health"], response_model=Health)
async def health() -> dict[str, str]:
    """On the event loop, not the thread pool: it answers while every thread is busy."""
    return {"status": "ok"}


def mount_static(app: FastAPI) -> None:
    """The dashboard's scripts and style sheet."""
    app.mount("/dashboard/static", StaticFiles(directory=STATIC), name="dashboard-static")
