"""`driftlab serve`: the REST API, the job runner and the 3D view in one process."""

from __future__ import annotations

import argparse
import socket

from driftlab.cli.options import db_url
from driftlab.cli.options import settings as command_settings
from driftlab.core.errors import ConfigError


def cmd_serve(args: argparse.Namespace) -> int:
    import uvicorn

    from driftlab.server.access_log import redact_access_log
    from driftlab.server.app import create_app
    from driftlab.server.slow_clients import with_header_deadline

    settings = command_settings()
    if args.host not in ("127.0.0.1", "localhost", "::1") and not settings.token:
        # Reachable from other machines: every client there could start, pause and delete jobs.
        raise ConfigError(f"--host {args.host}: serving beyond this machine needs DRIFTLAB_TOKEN (mutations then "
                          "need 'Authorization: Bearer <token>', the view /viser/?token=<token>); or bind 127.0.0.1")
    sock = listening_socket(args.host, args.port)  # before touching any job: a second server on a taken port
    # must leave the first one's jobs alone
    if args.dask:
        settings = settings.model_copy(update={"dask_address": args.dask})
    workers = args.workers or (None if settings.dask_address else 2)
    app = create_app(db_url(args.db), workers=workers, settings=settings)
    shown_host = "localhost" if args.host == "0.0.0.0" else args.host
    login = "?token=<DRIFTLAB_TOKEN>" if settings.token else ""
    base = f"http://{shown_host}:{args.port}"
    print(f"DriftLab: the dashboard on {base}/dashboard/{login}, the 3D view on {base}/viser/{login}, the API docs on "
          f"{base}/docs", flush=True)
    # uvicorn's keep-alive (5 s) equal to a client pool's idle expiry (httpx: 5 s) races it: a request sent on a
    # connection the server is closing is lost. Idle connections are closed by the header deadline instead.
    server = uvicorn.Server(uvicorn.Config(app, log_level="info", http=with_header_deadline(settings.header_timeout_s),
                                           timeout_keep_alive=int(settings.header_timeout_s) + 1))
    redact_access_log()  # after uvicorn's Config set its loggers up
    server.run(sockets=[sock])
    return 0


def listening_socket(host: str, port: int) -> socket.socket:
    """The server's bound, listening TCP socket (ConfigError naming --port if it is taken)."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    # IPPROTO_TCP named: asyncio turns Nagle's algorithm off (TCP_NODELAY) only on sockets that say they are TCP;
    # with it on, a response's body waited for the client's delayed ACK of its headers (~40 ms a request).
    sock = socket.socket(family, socket.SOCK_STREAM, socket.IPPROTO_TCP)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        raise ConfigError(f"--port {port} on {host}: {exc.strerror or exc}") from None
    sock.listen(2048)
    sock.set_inheritable(True)
    return sock
