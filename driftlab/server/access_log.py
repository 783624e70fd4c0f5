"""The server's log without the token: a page opened as ``/viser/?token=...`` would otherwise write the token into
every log line that records its first request (uvicorn's access log prints the path with its query), and a script
that opens the view's websocket as ``/viser?token=...`` into uvicorn's error log ("WebSocket /viser?token=..."
[accepted]), which uvicorn writes through ``uvicorn.error``, not the access log."""

from __future__ import annotations

import logging
import re

_TOKEN_QUERY = re.compile(r'(?<=[?&])token=[^&\s"]*', re.IGNORECASE)
REDACTED = "token=[redacted]"


def redact(path: str) -> str:
    return _TOKEN_QUERY.sub(REDACTED, path)


class RedactToken(logging.Filter):
    """On uvicorn's access logger: its records carry (client, method, path with query, version, status)."""

    def filter(self, record: logging.LogRecord) -> bool:
        if isinstance(record.args, tuple) and len(record.args) >= 3:
            args = list(record.args)
            args[2] = redact(str(args[2]))
            record.args = tuple(args)
        return True


class RedactTokenInMessage(logging.Filter):
    """On a handler: any record it writes, whatever logger it came from, with its message formatted and redacted."""

    def filter(self, record: logging.LogRecord) -> bool:
        message = record.getMessage()
        redacted = _TOKEN_QUERY.sub(REDACTED, message)
        if redacted != message:
            record.msg, record.args = redacted, None
        return True


# The loggers whose handlers write the server's output: uvicorn's ("uvicorn" carries uvicorn.error's records),
# its access log, and the root logger (the app's own, and any library's that propagate).
_WRITING_LOGGERS = ("uvicorn", "uvicorn.error", "uvicorn.access", "")


def redact_access_log() -> None:
    """Install the filters (after uvicorn configured its loggers): on the access logger (its path argument, before
    its formatter reads it), and on every handler that writes a line."""
    logger = logging.getLogger("uvicorn.access")
    if not any(isinstance(f, RedactToken) for f in logger.filters):
        logger.addFilter(RedactToken())
    for name in _WRITING_LOGGERS:
        for handler in logging.getLogger(name).handlers:
            if not any(isinstance(f, RedactTokenInMessage) for f in handler.filters):
                handler.addFilter(RedactTokenInMessage())
