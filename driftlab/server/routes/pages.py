"""The landing page and the health check."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import HTMLResponse

from driftlab.server.responses import Health

router = APIRouter()

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


@router.get("/", response_class=HTMLResponse, include_in_schema=False)
def landing() -> str:
    return LANDING_PAGE


@router.get("/api/health", tags=["health"], response_model=Health)
def health() -> dict[str, str]:
    return {"status": "ok"}
