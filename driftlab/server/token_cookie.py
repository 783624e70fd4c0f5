"""A page opened as ``?token=<DRIFTLAB_TOKEN>`` (the 3D view, the dashboard): the token moves into an HttpOnly,
SameSite=Strict cookie (Secure behind https) and the browser is sent to the same address without it, so the token
stays out of the address bar, the history, page scripts and any link copied from there (as Jupyter Server does
after the first load). The edge (driftlab.server.edge) takes the cookie as it takes the bearer header."""

from __future__ import annotations

from urllib.parse import urlencode

from fastapi import Request
from fastapi.responses import RedirectResponse, Response

from driftlab.server.edge import TOKEN_COOKIE, same_secret


def is_https(request: Request) -> bool:
    return request.url.scheme == "https" or request.headers.get("x-forwarded-proto", "").lower() == "https"


def token_to_cookie(request: Request, given: str) -> Response:
    """A 303 to the request's path without ``token``; with the cookie set when ``given`` is the token."""
    rest = [(k, v) for k, v in request.query_params.multi_items() if k != "token"]
    response = RedirectResponse(request.url.path + (f"?{urlencode(rest)}" if rest else ""), status_code=303)
    response.headers["Cache-Control"] = "no-store"
    token = request.app.state.settings.token
    if token and same_secret(given, token):
        response.set_cookie(TOKEN_COOKIE, given, httponly=True, samesite="strict", secure=is_https(request), path="/")
    return response
