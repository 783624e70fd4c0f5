"""Deadlines for slow clients, which uvicorn does not set: a request's line and headers must arrive within
``DRIFTLAB_HEADER_TIMEOUT_S`` of the connection (or of the previous response), else the connection is closed (1000
clients trickling a header byte a second held a connection each, for ever: nginx's ``client_header_timeout``);
a request body may not pause longer than ``DRIFTLAB_BODY_TIMEOUT_S`` between its chunks, else 408 (the edge,
driftlab.server.edge: nginx's ``client_body_timeout``).
"""

from __future__ import annotations

import asyncio

from uvicorn.protocols.http.h11_impl import H11Protocol


def with_header_deadline(header_timeout_s: float) -> type[H11Protocol]:
    """uvicorn's h11 protocol (``uvicorn.Config(http=...)``) closing a connection whose request headers take longer
    than ``header_timeout_s``."""

    class HeaderDeadlineH11Protocol(H11Protocol):
        _deadline: asyncio.TimerHandle | None = None

        def connection_made(self, transport) -> None:  # type: ignore[override]
            super().connection_made(transport)
            self._arm()

        def connection_lost(self, exc: Exception | None) -> None:
            self._disarm()
            super().connection_lost(exc)

        def handle_events(self) -> None:
            cycle = self.cycle
            super().handle_events()
            if self.cycle is not cycle:  # a request's headers are complete: its cycle began
                self._disarm()

        def handle_websocket_upgrade(self, event) -> None:
            self._disarm()  # the websocket protocol takes the connection over
            super().handle_websocket_upgrade(event)

        def on_response_complete(self) -> None:
            super().on_response_complete()
            if not self.transport.is_closing() and (self.cycle is None or self.cycle.response_complete):
                self._arm()  # the next request's headers

        def _arm(self) -> None:
            self._disarm()
            self._deadline = self.loop.call_later(header_timeout_s, self._headers_too_slow)

        def _disarm(self) -> None:
            if self._deadline is not None:
                self._deadline.cancel()
                self._deadline = None

        def _headers_too_slow(self) -> None:
            self._deadline = None
            if not self.transport.is_closing():
                self.transport.close()

    return HeaderDeadlineH11Protocol
