"""The access log without the token: a page opened as ``/viser/?token=...`` would otherwise write the token into
every log line that records its first request (uvicorn's access log prints the path with its query)."""

from __future__ import annotations

import logging
import re

_TOKEN_QUERY = re.compile(r"(?<=[?&])token=[^&\s]*", re.IGNORECASE)
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


def redact_access_log() -> None:
    """Install the filter (after uvicorn configured its loggers)."""
    logger = logging.getLogger("uvicorn.access")
    if not any(isinstance(f, RedactToken) for f in logger.filters):
        logger.addFilter(RedactToken())
