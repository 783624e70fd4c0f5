"""The part of the OpenAPI document that the edge (driftlab.server.edge) decides rather than the routes: it
answers before any route runs, so its answers are added here by the edge's own rules, not route by route.

- every operation: 400 for a Host that is not this server's;
- a mutating API operation (POST, PUT, PATCH, DELETE under /api): 413 for a body over the limit, and without a
  token, the 403 for a request from another origin;
- with a token set, the bearer security scheme and its 401 on every operation that needs it (every API operation
  but the health check; the reads only unless DRIFTLAB_PUBLIC_READS opens them).
"""

from __future__ import annotations

from typing import Any

from fastapi import FastAPI

from driftlab.server.edge import MUTATING, needs_token
from driftlab.server.responses import ERROR_DESCRIPTIONS

SCHEME = "bearerToken"
ERROR_REF = {"$ref": "#/components/schemas/ErrorBody"}  # the routes' error model: every router documents it


def document_edge(app: FastAPI, *, token_set: bool, public_reads: bool = False) -> None:
    """Make ``app.openapi()`` return FastAPI's document with the edge's answers (built once, then cached)."""
    generate = app.openapi

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:  # generate() caches the document in app.openapi_schema
            add_edge(generate(), token_set=token_set, public_reads=public_reads)
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]


def add_edge(schema: dict[str, Any], *, token_set: bool, public_reads: bool = False) -> None:
    if token_set:
        schema.setdefault("components", {}).setdefault("securitySchemes", {})[SCHEME] = {
            "type": "http", "scheme": "bearer", "description": "the server's DRIFTLAB_TOKEN"}
    for path, operations in schema.get("paths", {}).items():
        for method, operation in operations.items():
            codes = [400]
            if method.upper() in MUTATING and path.startswith("/api"):
                codes += [408, 413] if token_set else [408, 413, 403]
            if token_set and needs_token(method, path, public_reads=public_reads):
                codes.append(401)
                operation["security"] = [{SCHEME: []}]
            responses = operation.setdefault("responses", {})
            for code in codes:
                responses.setdefault(str(code), {"description": ERROR_DESCRIPTIONS[code],
                                                 "content": {"application/json": {"schema": ERROR_REF}}})
