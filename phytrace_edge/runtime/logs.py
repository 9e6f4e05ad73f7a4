"""Logging: one line per record, as text or JSON (LOG_FORMAT), secrets masked.

The API key is never passed to a logger on purpose; the redaction filter is the
second line of defence, should a library ever echo a header or a URL with it.
"""

from __future__ import annotations

import logging
import sys
from collections.abc import Iterable
from typing import Any

import orjson

from phytrace_edge.redact import leak_forms, redact
from phytrace_edge.udm.event import format_timestamp

TEXT_FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"


class JsonFormatter(logging.Formatter):
    def format(self, record: logging.LogRecord) -> str:
        document: dict[str, Any] = {
            "ts": format_timestamp(record.created),
            "level": record.levelname,
            "logger": record.name,
            "message": record.getMessage(),
        }
        if record.exc_info:
            document["exception"] = record.exc_text or self.formatException(record.exc_info)
        return orjson.dumps(document).decode()


class RedactSecrets(logging.Filter):
    """Masks every form of the secrets (as is, escaped, percent-encoded) in a record's
    message and in its exception's text."""

    def __init__(self, secrets: Iterable[str]) -> None:
        super().__init__()
        forms = {form for s in secrets if len(s) >= 4 for form in leak_forms(s)}
        self._forms = sorted(forms, key=len, reverse=True)

    def filter(self, record: logging.LogRecord) -> bool:
        if not self._forms:
            return True
        message = record.getMessage()
        masked = redact(message, self._forms)
        if masked != message:
            record.msg, record.args = masked, None
        if record.exc_info:
            text = logging.Formatter().formatException(record.exc_info)
            record.exc_text = redact(text, self._forms)
        return True


def configure_logging(level: str, fmt: str, secrets: Iterable[str] = ()) -> None:
    """Route every log record to stderr, one line each."""
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(JsonFormatter() if fmt == "json" else logging.Formatter(TEXT_FORMAT))
    handler.addFilter(RedactSecrets(secrets))
    root = logging.getLogger()
    root.handlers[:] = [handler]
    root.setLevel(level)
    # one INFO line per HTTP request would drown the log; failures are logged by the sender
    logging.getLogger("httpx").setLevel(max(logging.WARNING, root.level))
