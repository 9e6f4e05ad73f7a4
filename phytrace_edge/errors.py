"""Errors of phytrace-edge.

Every error the bridge raises on purpose derives from ``PhytraceError`` and carries a
one-line message that names the thing and, where there is one, the fix. The CLI prints
that line and exits non-zero; it never prints a traceback for these.

    PhytraceError
    ├── ConfigError          a setting has a value that is not allowed
    └── MalformedMessage     a ROS message cannot be turned into a reading

Later stages add their own branches here (queue and send errors), so that whether an
error is retryable is its type, never a string match.
"""

from __future__ import annotations


class PhytraceError(Exception):
    """Base of every error phytrace-edge raises on purpose."""


class ConfigError(PhytraceError):
    """A setting has a value that is not allowed.

    The message names the setting, the offending value (redacted for secrets) and what
    is allowed, e.g. ``SAMPLE_RATE_HZ='-1': must be a number > 0 and <= 1000``.
    """


class MalformedMessage(PhytraceError):
    """A ROS message cannot be turned into a reading; ``reason`` is a short count key."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail
