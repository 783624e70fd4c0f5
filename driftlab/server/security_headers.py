"""Security headers on every HTTP response (OWASP's secure headers; Jupyter Server's frame-ancestors):

- no page of this service may be framed by another site (``frame-ancestors 'none'``, ``X-Frame-Options: DENY``): a
  framed dashboard would take a user's clicks (clickjacking);
- a Content-Security-Policy: scripts from this origin only, no plugins, no frames, no base or form targets elsewhere.
  viser's client page boots from one inline script that decompresses its bundle (WebAssembly) and inserts it as an
  inline module, so that page alone allows inline script and WebAssembly; what a user typed reaches it only as
  escaped text (driftlab.web.markup);
- ``X-Content-Type-Options: nosniff`` (a download is never run as a script) and ``Referrer-Policy: no-referrer``
  (the address, a token in it included, never leaves in a Referer header).
"""

from __future__ import annotations

_COMMON = ("default-src 'self'; style-src 'self' 'unsafe-inline'; img-src 'self' data: blob:; "
           "font-src 'self' data:; connect-src 'self'; object-src 'none'; frame-src 'none'; child-src 'self' blob:; "
           "worker-src 'self' blob:; base-uri 'none'; form-action 'self'; frame-ancestors 'none'")
PAGE_POLICY = f"{_COMMON}; script-src 'self'"
# viser's client reads the scene's images and environment map from blob: and data: URLs it makes itself.
VIEWER_POLICY = (_COMMON.replace("connect-src 'self'", "connect-src 'self' blob: data:")
                 + "; script-src 'self' 'unsafe-inline' 'wasm-unsafe-eval' blob:")
VIEWER_PREFIX = "/viser/"
REPLAY_SUFFIX = "/replay.html"  # viser's standalone player, opened from the dashboard (driftlab.server.view)
# The Swagger UI page loads its bundle from jsDelivr, pinned with integrity (driftlab.server.docs_page), and starts
# it from an inline script.
DOCS_PATHS = frozenset({"/docs"})
DOCS_POLICY = (_COMMON.replace("style-src 'self'", "style-src 'self' https://cdn.jsdelivr.net")
               + "; script-src 'self' 'unsafe-inline' https://cdn.jsdelivr.net")

_FIXED = [(b"x-frame-options", b"DENY"), (b"x-content-type-options", b"nosniff"),
          (b"referrer-policy", b"no-referrer"), (b"cross-origin-opener-policy", b"same-origin")]


def policy_for(path: str) -> str:
    """The Content-Security-Policy of the page or response at ``path``."""
    if path in DOCS_PATHS:
        return DOCS_POLICY
    return VIEWER_POLICY if path.startswith(VIEWER_PREFIX) or path.endswith(REPLAY_SUFFIX) else PAGE_POLICY


class SecurityHeaders:
    """A pure ASGI middleware: adds the headers to every response's start, refusals of the edge included."""

    def __init__(self, app) -> None:
        self.app = app

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        policy = policy_for(scope.get("path", "")).encode()

        async def with_headers(message):
            if message["type"] == "http.response.start":
                present = {name.lower() for name, _ in message.get("headers", ())}
                extra = [(name, value) for name, value in [*_FIXED, (b"content-security-policy", policy)]
                         if name not in present]
                message = {**message, "headers": [*message.get("headers", ()), *extra]}
            await send(message)

        await self.app(scope, receive, with_headers)
