"""viser servers for the view: on loopback ports that only the API's relay (driftlab.server.view) can use.

viser's own websocket server accepts any connection to its port, from any process of the machine and from any web
page a local browser opens (a websocket has no same-origin rule), and sends the job list to whoever connects. Its
handshake therefore has to carry a secret this process made and only the relay sends (``RELAY_HEADER``); the
check sits in the handshake's ``process_request`` hook of the websockets server that viser starts, which also
answers viser's plain HTTP requests for its client files: nothing on that port answers a stranger.
"""

from __future__ import annotations

import contextlib
import http
import inspect
import io
import secrets
import threading

import viser
import websockets.asyncio.server

RELAY_HEADER = "x-driftlab-relay"
RELAY_SECRET = secrets.token_urlsafe(32)  # this process's; the relay sends it, nothing outside the process knows it
_SERVE_LOCK = threading.Lock()  # the hook is set while one viser server starts, so starts take turns


def quiet_viser_server(**kwargs) -> viser.ViserServer:
    """A viser server without viser's banner, answering only the relay: users open the API's port, never this one."""
    with _SERVE_LOCK, _only_the_relay(), contextlib.redirect_stdout(io.StringIO()):
        # viser 1.1 prints the banner even with verbose=False; it binds before the constructor returns.
        return viser.ViserServer(verbose=False, **kwargs)


def relay_knows_secret(request) -> bool:
    given = request.headers.get(RELAY_HEADER, "")
    return secrets.compare_digest(given.encode("utf-8", "surrogateescape"), RELAY_SECRET.encode())


def _gated(process_request):
    async def gate(connection, request):
        if not relay_knows_secret(request):
            return connection.respond(http.HTTPStatus.FORBIDDEN, "only the DriftLab server's relay connects here\n")
        if process_request is None:
            return None
        answer = process_request(connection, request)
        return await answer if inspect.isawaitable(answer) else answer
    return gate


@contextlib.contextmanager
def _only_the_relay():
    original = websockets.asyncio.server.serve

    def serve(handler, *args, process_request=None, **kwargs):
        return original(handler, *args, process_request=_gated(process_request), **kwargs)

    websockets.asyncio.server.serve = serve
    try:
        yield
    finally:
        websockets.asyncio.server.serve = original
