"""What routes need from the app: its storage, its job runner, the token check."""

from __future__ import annotations

from urllib.parse import urlsplit

from fastapi import HTTPException, Request
from sqlalchemy.orm import Session, sessionmaker

from driftlab.server.edge import TOKEN_COOKIE, same_secret
from driftlab.server.evaluation_pages import EvaluationPages
from driftlab.server.trajectory_documents import TrajectoryDocuments
from driftlab.settings import Settings


def factory(request: Request) -> sessionmaker[Session]:
    return request.app.state.factory


def evaluation_pages(request: Request) -> EvaluationPages:
    return request.app.state.evaluation_pages


def trajectory_documents(request: Request) -> TrajectoryDocuments:
    return request.app.state.trajectory_documents


def wake_runner(request: Request) -> None:
    runner = getattr(request.app.state, "runner", None)
    if runner is not None:
        runner.wake()


def require_token(request: Request) -> None:
    """The edge refuses first (driftlab.server.edge); this holds for an app without it too. The header is read
    here rather than declared as a parameter: the OpenAPI document states it as the bearer security scheme
    (driftlab.server.openapi), and only when a token is set."""
    settings: Settings = request.app.state.settings
    token = settings.token
    if not token:
        return
    authorization = request.headers.get("authorization")
    if authorization and same_secret(authorization, f"Bearer {token}"):
        return
    # The cookie a page opened with ?token= got (driftlab.server.token_cookie), from this origin only.
    origin, host = request.headers.get("origin"), request.headers.get("host", "")
    same_origin = origin is None or urlsplit(origin).netloc.lower() == host.lower()
    cookie = request.cookies.get(TOKEN_COOKIE)
    if not (same_origin and cookie and same_secret(cookie, token)):
        raise HTTPException(401, "this endpoint needs 'Authorization: Bearer <DRIFTLAB_TOKEN>'")
