"""The 3D view on the API's port: viser's client page at ``/viser/``, its websocket relayed to the viser
server on a loopback port that answers only this relay (driftlab.web.viser_server), and episode recordings as
downloads.

viser 1.1 rejects a websocket without its subprotocol (``viser-v<version>``), so the relay accepts with the
browser's subprotocol and passes the same one upstream.
"""

from __future__ import annotations

import asyncio
import gzip
import threading
from collections import OrderedDict
from collections.abc import Callable
from pathlib import Path

import viser
import websockets
from fastapi import Depends, FastAPI, Request, WebSocket, WebSocketDisconnect
from fastapi.responses import HTMLResponse, RedirectResponse, Response
from sqlalchemy.orm import Session, sessionmaker

from driftlab.db import storage
from driftlab.server.heavy_reads import heavy_read
from driftlab.server.responses import ViewStatus, errors, media
from driftlab.server.schemas import EvaluationId
from driftlab.server.token_cookie import token_to_cookie
from driftlab.web.recording import EpisodeRecorder
from driftlab.web.sources import frames_of_evaluation, track_of_spec
from driftlab.web.viser_server import RELAY_HEADER, RELAY_SECRET

CLIENT_PAGE = Path(viser.__file__).parent / "client" / "build" / "index.html"
MAX_MESSAGE_BYTES = 50 * 1024 * 1024  # viser's own limit


class RecordingCache:
    """Recordings by (evaluation id, kind): a stored evaluation never changes, so neither does its recording."""

    def __init__(self, factory: sessionmaker[Session], size: int = 16) -> None:
        self.factory = factory
        self.recorder = EpisodeRecorder()
        self.size = size
        self._cache: OrderedDict[tuple[int, str], bytes] = OrderedDict()
        self._lock = threading.Lock()  # routes run in a thread pool; recordings are made one at a time anyway

    def get(self, evaluation_id: int, kind: str) -> bytes:
        key = (evaluation_id, kind)
        with self._lock:
            if key not in self._cache:
                self._cache[key] = self._record(evaluation_id, kind)
                while len(self._cache) > self.size:
                    self._cache.popitem(last=False)
            self._cache.move_to_end(key)
            return self._cache[key]

    def _record(self, evaluation_id: int, kind: str) -> bytes:
        frames = frames_of_evaluation(self.factory, evaluation_id)  # raises NotFound first
        with storage.snapshot(self.factory) as session:
            track = track_of_spec(storage.get_evaluation(session, evaluation_id=evaluation_id).job.spec)
        if kind == "viser":
            return self.recorder.viser_file(frames, track)
        return self.recorder.html(frames, track).encode()


TOO_MANY_TABS = 1013  # the websocket close code for "try again later"


def add_view_routes(app: FastAPI, upstream_port: Callable[[], int | None], recordings: RecordingCache,
                    n_clients: Callable[[], int], max_tabs: int = 20) -> None:
    """``max_tabs``: relayed tabs at once; one more is accepted and closed at once with code 1013 (try again
    later) and the reason: each tab streams a car at 30 Hz from this process (50 tabs: the health check's p99 4 s)."""
    page = CLIENT_PAGE.read_bytes()
    tabs = {"open": 0}  # changed on the event loop only
    page_gzip = gzip.compress(page)

    @app.get("/api/view", tags=["view"], response_model=ViewStatus)
    def view_status() -> dict[str, int]:
        """The 3D view: its open browser tabs."""
        return {"clients": n_clients()}

    @app.get("/viser", include_in_schema=False)
    def view_redirect(request: Request) -> RedirectResponse:
        query = f"?{request.url.query}" if request.url.query else ""
        return RedirectResponse(f"/viser/{query}")

    @app.get("/viser/", include_in_schema=False)
    def view_page(request: Request) -> Response:
        given = request.query_params.get("token")
        if given is not None:
            return token_to_cookie(request, given)
        if "gzip" in request.headers.get("accept-encoding", ""):
            return Response(page_gzip, media_type="text/html", headers={"Content-Encoding": "gzip"})
        return HTMLResponse(page)

    @app.websocket("/viser")
    async def view_socket(websocket: WebSocket) -> None:
        if tabs["open"] >= max_tabs:
            await websocket.accept(subprotocol=next((p for p in websocket.scope.get("subprotocols") or []
                                                     if p.startswith("viser-v")), None))
            await websocket.close(code=TOO_MANY_TABS, reason=f"{max_tabs} view tabs are open "
                                  "(DRIFTLAB_MAX_VIEW_TABS): try again later")
            return
        tabs["open"] += 1
        try:
            await relay(websocket, upstream_port())
        finally:
            tabs["open"] -= 1

    @app.get("/api/evaluations/{evaluation_id}/recording.viser", tags=["view"], response_class=Response,
             dependencies=[Depends(heavy_read)], responses={
        **media("application/octet-stream", {"type": "string", "format": "binary"}, "a viser recording"),
        **errors(404, 422, 503)})
    def recording(evaluation_id: EvaluationId) -> Response:
        """The episode as a viser recording: open it with ``/viser/?playbackPath=<this URL>``."""
        return Response(recordings.get(evaluation_id, "viser"), media_type="application/octet-stream",
                        headers={"Content-Disposition": f'attachment; filename="evaluation-{evaluation_id}.viser"'})

    @app.get("/api/evaluations/{evaluation_id}/replay.html", tags=["view"], response_class=Response,
             dependencies=[Depends(heavy_read)], responses={
        **media("text/html", {"type": "string"}, "a page that replays the episode"), **errors(404, 422, 503)})
    def replay(evaluation_id: EvaluationId) -> Response:
        """A standalone HTML page that replays the episode with no server (shown in the browser; saved, it plays
        offline): the job, the evaluation, its J and theta, the plant and the seed beside the 3D player and the
        state plots."""
        return Response(recordings.get(evaluation_id, "html"), media_type="text/html",
                        headers={"Content-Disposition": f'inline; filename="evaluation-{evaluation_id}.html"'})


async def relay(websocket: WebSocket, port: int | None) -> None:
    offered = websocket.scope.get("subprotocols") or []
    subprotocol = next((p for p in offered if p.startswith("viser-v")), None)
    if subprotocol is None or port is None:
        await websocket.close(code=1002 if subprotocol is None else 1013)
        return
    async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=[subprotocol],
                                  additional_headers={RELAY_HEADER: RELAY_SECRET},
                                  max_size=MAX_MESSAGE_BYTES, compression=None) as upstream:
        await websocket.accept(subprotocol=subprotocol)
        tasks = [asyncio.create_task(_browser_to_viser(websocket, upstream)),
                 asyncio.create_task(_viser_to_browser(upstream, websocket))]
        _, pending = await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
        for task in pending:
            task.cancel()
    try:
        await websocket.close()
    except (RuntimeError, WebSocketDisconnect):  # already closed by the browser
        pass


async def _browser_to_viser(websocket: WebSocket, upstream) -> None:
    try:
        while True:
            message = await websocket.receive()
            if message["type"] == "websocket.disconnect":
                return
            data = message.get("bytes")
            await upstream.send(data if data is not None else message.get("text", ""))
    except (WebSocketDisconnect, websockets.ConnectionClosed):
        return


async def _viser_to_browser(upstream, websocket: WebSocket) -> None:
    try:
        async for data in upstream:
            if isinstance(data, bytes):
                await websocket.send_bytes(data)
            else:
                await websocket.send_text(data)
    except (WebSocketDisconnect, websockets.ConnectionClosed, RuntimeError):
        return
