"""Errors of phytrace-edge.

Every error the bridge raises on purpose derives from ``PhytraceError`` and carries a
one-line message that names the thing and, where there is one, the fix. The CLI prints
that line and exits non-zero; it never prints a traceback for these.

    PhytraceError
    ├── ConfigError          a setting has a value that is not allowed
    ├── MalformedMessage     a ROS message cannot be turned into a reading
    ├── QueueError           the queue database cannot do what was asked
    │   ├── QueueBusyError   another process held the write lock past the busy timeout
    │   └── QueueFullError   the disk is full (SQLITE_FULL) for a write that must happen
    └── SendError            a batch did not reach PhyCloud this time
        └── TransientSendError   retry it: 408/425/429/5xx, timeouts, connection errors
            └── EndpointRefusedError  retry it, but slowly and loudly: 401/403 (key),
                                      415 (encoding), other unexpected answers (config)

A batch PhyCloud rejects as bad data (400/422/413) is not an error: the sender splits
it and dead-letters the offending events. No SendError ever drops data.

Whether an error is worth retrying is its type, never a string match.
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


class QueueError(PhytraceError):
    """The queue database cannot do what was asked."""


class QueueBusyError(QueueError):
    """Another process held the queue's write lock for longer than the busy timeout."""


class QueueFullError(QueueError):
    """The disk under the queue is full; free space or lower QUEUE_MAX_BYTES."""


class SendError(PhytraceError):
    """A batch did not reach PhyCloud this time."""


class TransientSendError(SendError):
    """Worth retrying with backoff; ``retry_after`` is the server's wish, in seconds."""

    def __init__(self, message: str, status: int | None = None, retry_after: float | None = None):
        super().__init__(message)
        self.status = status
        self.retry_after = retry_after


class EndpointRefusedError(TransientSendError):
    """PhyCloud refuses us for a reason data cannot fix (the key, the encoding, the
    endpoint address): keep the data, back off long, and tell the operator."""
