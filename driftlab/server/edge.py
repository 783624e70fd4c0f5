"""The service's edge, checked before any route runs and before any request body is read (a pure ASGI
middleware, so nothing is buffered first):

- the Host header names this machine (127.0.0.1, localhost, ::1) or a host of ``DRIFTLAB_ALLOWED_HOSTS``: a page
  on another site cannot reach the API through DNS rebinding (400 otherwise);
- an API request (under /api, but /api/health) carries the token when one is set, as a bearer header or, from
  this origin, as the cookie a page opened with ``?token=`` got (401 before any route sees its body); reads too,
  unless ``DRIFTLAB_PUBLIC_READS`` opens them (configs, notes and trajectories are a lab's unpublished work);
  without a token, a mutating request (POST, PUT, PATCH, DELETE) sent by a browser from another origin is refused
  (403): body-less POSTs are "simple" cross-site requests that no CORS preflight stops;
- a request body larger than ``DRIFTLAB_MAX_BODY_BYTES`` is refused (413), by its Content-Length or, for a
  chunked body, as soon as the bytes read pass the limit; one that pauses longer than ``DRIFTLAB_BODY_TIMEOUT_S``
  between chunks is a 408 (headers have their deadline in the protocol: driftlab.server.slow_clients);
- the /viser websocket (the 3D view, whose what-if panel runs episodes) opens only from this origin, and with the
  token (the ``driftlab_token`` cookie that ``/viser/?token=...`` sets) when one is set.
"""

from __future__ import annotations

import asyncio
import json
import secrets
from functools import partial
from http.cookies import SimpleCookie
from urllib.parse import parse_qs, urlsplit

LOCAL_HOSTS = frozenset({"127.0.0.1", "localhost", "::1"})
MUTATING = frozenset({"POST", "PUT", "PATCH", "DELETE"})
OPEN_PATHS = frozenset({"/api/health"})  # a load balancer's or a container's liveness probe has no token


def needs_token(method: str, path: str, *, public_reads: bool) -> bool:
    """Whether a request needs the token when one is set."""
    if not path.startswith("/api") or path in OPEN_PATHS:
        return False
    return method.upper() in MUTATING or not public_reads
TOKEN_COOKIE = "driftlab_token"


def host_name(host_header: str) -> str:
    """'localhost:8000' -> 'localhost'; '[::1]:8000' -> '::1'."""
    host = host_header.strip().lower()
    if host.startswith("["):
        return host[1:host.find("]")] if "]" in host else host
    return host.rsplit(":", 1)[0] if host.count(":") == 1 else host


def same_secret(given: str, expected: str) -> bool:
    """Constant-time comparison of any text a client sent (a non-ASCII token is a wrong token, never an error)."""
    return secrets.compare_digest(given.encode("utf-8", "surrogateescape"), expected.encode("utf-8", "surrogateescape"))


class EdgeGuard:
    def __init__(self, app, *, token: str | None, allowed_hosts: frozenset[str], max_body_bytes: int,
                 public_reads: bool = False, body_timeout_s: float = 30.0) -> None:
        self.app = app
        self.body_timeout_s = body_timeout_s
        self.token = token or None
        self.public_reads = public_reads
        self.allowed_hosts = LOCAL_HOSTS | {h.lower() for h in allowed_hosts}
        self.max_body_bytes = max_body_bytes

    async def __call__(self, scope, receive, send):
        if scope["type"] not in ("http", "websocket"):
            return await self.app(scope, receive, send)
        refuse = partial(self._refuse, scope, receive, send)
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope.get("headers", ())}
        host = headers.get("host", "")
        if "*" not in self.allowed_hosts and host_name(host) not in self.allowed_hosts:
            return await refuse(400, f"host: {host!r} is not this server's (127.0.0.1, localhost, "
                                "or DRIFTLAB_ALLOWED_HOSTS)")
        origin = headers.get("origin")
        foreign = origin is not None and not self._same_origin(origin, host)
        if scope["type"] == "websocket":
            if foreign:
                return await refuse(403, f"origin: {origin!r} may not open the view's websocket")
            if self.token and not self._websocket_token_ok(scope, headers):
                return await refuse(401, "token: open the view as /viser/?token=<DRIFTLAB_TOKEN>")
            return await self.app(scope, receive, send)
        if self.token and needs_token(scope["method"], scope["path"], public_reads=self.public_reads):
            if not (same_secret(headers.get("authorization", ""), f"Bearer {self.token}")
                    or (not foreign and self._cookie_token_ok(headers))):
                return await refuse(401, "this endpoint needs 'Authorization: Bearer <DRIFTLAB_TOKEN>'")
        if not self.token and foreign and scope["method"] in MUTATING and scope["path"].startswith("/api"):
            return await refuse(403, f"origin: a request from {origin!r} may not change "
                                "anything here (set DRIFTLAB_TOKEN to allow authenticated clients)")
        length = headers.get("content-length")
        if length is not None and length.isdigit() and int(length) > self.max_body_bytes:
            return await refuse(413, self._too_large())
        return await self._limited(scope, receive, send)

    def _same_origin(self, origin: str, host: str) -> bool:
        parts = urlsplit(origin)
        return parts.netloc.lower() == host.strip().lower() or (
            parts.hostname or "").lower() in (self.allowed_hosts - LOCAL_HOSTS)

    def _cookie_token_ok(self, headers) -> bool:
        """The HttpOnly cookie that a page opened with ``?token=`` got (driftlab.server.token_cookie)."""
        cookie = SimpleCookie(headers.get("cookie", ""))
        return TOKEN_COOKIE in cookie and same_secret(cookie[TOKEN_COOKIE].value, self.token)

    def _websocket_token_ok(self, scope, headers) -> bool:
        given = parse_qs(scope.get("query_string", b"").decode("latin-1")).get("token", [""])[0]
        return (bool(given) and same_secret(given, self.token)) or self._cookie_token_ok(headers)

    def _too_large(self) -> str:
        return f"body: larger than {self.max_body_bytes} bytes (DRIFTLAB_MAX_BODY_BYTES)"

    async def _limited(self, scope, receive, send):
        """The app, with a body that may not pass the limit while it is read (chunked bodies have no length)."""
        state = {"read": 0, "started": False, "refused": False, "body_done": False}

        async def limited_receive():
            if state["body_done"]:
                return await receive()  # after the body: waiting for a disconnect may last
            try:
                message = await asyncio.wait_for(receive(), self.body_timeout_s)
            except TimeoutError:
                if not state["started"]:
                    await self._send_json(send, 408, f"body: no byte for {self.body_timeout_s:g} s "
                                                     "(DRIFTLAB_BODY_TIMEOUT_S)")
                    state["started"] = state["refused"] = True
                return {"type": "http.disconnect"}
            state["body_done"] = message["type"] != "http.request" or not message.get("more_body", False)
            if message["type"] == "http.request":
                state["read"] += len(message.get("body", b""))
                if state["read"] > self.max_body_bytes:
                    if not state["started"]:
                        await self._send_json(send, 413, self._too_large())
                        state["started"] = state["refused"] = True
                    return {"type": "http.disconnect"}  # the route stops reading; its answer is dropped
            return message

        async def guarded_send(message):
            if state["refused"]:
                return
            if message["type"] == "http.response.start":
                state["started"] = True
            await send(message)

        await self.app(scope, limited_receive, guarded_send)

    async def _refuse(self, scope, receive, send, status: int, detail: str):
        if scope["type"] == "websocket":
            # Before the handshake is accepted: the server answers the upgrade with 403.
            await send({"type": "websocket.close", "code": 1008, "reason": detail[:120]})
            return
        await self._drain_small_body(scope, receive)
        await self._send_json(send, status, detail)

    async def _drain_small_body(self, scope, receive) -> None:
        """Read (and drop) a body whose declared length is within the limit before refusing it: the refusal closes
        the connection, and a close with unread bytes is a TCP reset that can destroy the answer on its way to the
        client. A body of unknown or too large a length stays unread (refused before a byte of it is read)."""
        length = dict(scope.get("headers", ())).get(b"content-length", b"")
        if not length.isdigit() or not 0 < int(length) <= self.max_body_bytes:
            return
        read = 0
        while read < int(length):
            try:
                message = await asyncio.wait_for(receive(), self.body_timeout_s)
            except TimeoutError:
                return  # a held body: refused without it
            if message["type"] != "http.request":
                return
            read += len(message.get("body", b""))
            if not message.get("more_body", False):
                return

    @staticmethod
    async def _send_json(send, status: int, detail: str):
        body = json.dumps({"detail": detail}).encode()
        await send({"type": "http.response.start", "status": status,
                    "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode()),
                                (b"connection", b"close")]})
        await send({"type": "http.response.body", "body": body})
