"""Logging: one line per record, as text or JSON (LOG_FORMAT), secrets masked.

The API key is never passed to a logger on purpose; the redaction filter is the
second line of defence, should a library ever echo a header or a URL with it.

Under systemd, stderr goes to the journal (systemd says so in ``JOURNAL_STREAM``):
each line then starts with its syslog priority (``<4>`` for WARNING, sd-daemon(3)), so
``journalctl -p warning`` finds warnings and errors; journald strips the prefix.
"""

from __future__ import annotations

import json
import logging
import os
import sys
import time
from collections.abc import Iterable, Mapping
from typing import Any

from phytrace_edge.redact import KNOWN, redact, remember
from phytrace_edge.udm.event import format_timestamp

TEXT_FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"


# logging level -> syslog priority (sd-daemon(3): SD_ERR, SD_WARNING, ...)
PRIORITIES = ((logging.CRITICAL, 2), (logging.ERROR, 3), (logging.WARNING, 4), (logging.INFO, 6))


def priority(levelno: int) -> int:
    return next((p for level, p in PRIORITIES if levelno >= level), 7)


class JournalPriorities(logging.Formatter):
    """Wraps a formatter: every line of a record starts with ``<N>``, its priority
    (a traceback's lines too, or journald would file them as info)."""

    def __init__(self, inner: logging.Formatter) -> None:
        super().__init__()
        self._inner = inner

    def format(self, record: logging.LogRecord) -> str:
        prefix = f"<{priority(record.levelno)}>"
        return "\n".join(prefix + line for line in self._inner.format(record).split("\n"))


def stderr_is_the_journal(env: Mapping[str, str], stream: object = sys.stderr) -> bool:
    """Whether ``stream`` is the journal stream systemd connected (``JOURNAL_STREAM``
    is ``device:inode`` of it; a child whose stderr was redirected does not match)."""
    device, _, inode = env.get("JOURNAL_STREAM", "").partition(":")
    try:
        info = os.fstat(stream.fileno())  # type: ignore[attr-defined]
        return (info.st_dev, info.st_ino) == (int(device), int(inode))
    except (ValueError, OSError, AttributeError):
        return False


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
        # the standard library's encoder: this module is on every command's start-up path
        return json.dumps(document, ensure_ascii=False, separators=(",", ":"))


class RedactSecrets(logging.Filter):
    """Masks every form of the secrets (as is, escaped, percent-encoded) in a record's
    message and in its exception's text."""

    def __init__(self, secrets: Iterable[str]) -> None:
        super().__init__()
        for secret in secrets:
            remember(secret)  # with the keys read later (a key file, a rotation)

    def filter(self, record: logging.LogRecord) -> bool:
        forms = KNOWN.forms
        if not forms:
            return True
        message = record.getMessage()
        masked = redact(message, forms)
        if masked != message:
            record.msg, record.args = masked, None
        if record.exc_info:
            text = logging.Formatter().formatException(record.exc_info)
            record.exc_text = redact(text, forms)
        return True


def configure_logging(
    level: str, fmt: str, secrets: Iterable[str] = (), env: Mapping[str, str] | None = None
) -> None:
    """Route every log record to stderr, one line each (with journal priorities when
    ``env``, the process environment, says stderr is the journal)."""
    handler = logging.StreamHandler(sys.stderr)
    formatter = JsonFormatter() if fmt == "json" else logging.Formatter(TEXT_FORMAT)
    if env is not None and stderr_is_the_journal(env):
        formatter = JournalPriorities(formatter)
    handler.setFormatter(formatter)
    handler.addFilter(RedactSecrets(secrets))
    root = logging.getLogger()
    root.handlers[:] = [handler]
    root.setLevel(level)
    # one INFO line per HTTP request would drown the log; failures are logged by the sender
    logging.getLogger("httpx").setLevel(max(logging.WARNING, root.level))


class RepeatedLine:
    """A trouble that repeats (a queue that cannot be written, every beat): logged the
    first time, then as one summary every ``every_s`` with how often it happened, and
    once more when it clears; not a line per occurrence."""

    def __init__(self, what: str, every_s: float, logger: logging.Logger | None = None) -> None:
        self.what = what
        self.every_s = every_s
        self._log = logger or logging.getLogger("phytrace_edge.runtime")
        self._since: float | None = None
        self._reported_at = 0.0
        self._count = 0

    def report(self, line: str, now: float | None = None) -> None:
        now = time.monotonic() if now is None else now
        self._count += 1
        if self._since is None:
            self._since = self._reported_at = now
            self._count = 0
            self._log.error("%s", line)
        elif now - self._reported_at >= self.every_s:
            self._log.error(
                "%s (again %d time(s) in %.0f s)", line, self._count, now - self._reported_at
            )
            self._reported_at, self._count = now, 0

    def clear(self, now: float | None = None) -> None:
        if self._since is not None:
            now = time.monotonic() if now is None else now
            self._log.warning("%s works again after %.0f s", self.what, now - self._since)
            self._since = None
