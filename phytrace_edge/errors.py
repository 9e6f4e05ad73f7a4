"""Errors of phytrace-edge.

Every error the bridge raises on purpose derives from ``PhytraceError`` and carries a
one-line message that names the thing and, where there is one, the fix. The CLI prints
that line and exits with the error's ``exit_code``; it never prints a traceback for these.

    PhytraceError            (exit 4: the bridge could not do its work)
    ├── ConfigError          (exit 2) a setting or argument has a value that is not allowed
    ├── StageFailedError     (exit 5) a thread of the service could not be kept alive
    ├── MalformedMessage     a ROS message cannot be turned into a reading
    ├── QueueError           the queue database cannot do what was asked
    │   ├── QueueBusyError   another process held the write lock past the busy timeout
    │   ├── QueueFullError   the disk is full (SQLITE_FULL) for a write that must happen
    │   └── QueueDamagedError  SQLite found the file corrupt, or not a database
    └── SendError            a batch did not reach PhyCloud this time
        └── TransientSendError   retry it: 408/425/429/5xx, timeouts, connection errors
            ├── UnexpectedAnswerError  retry it: a 2xx that is not PhyCloud's answer
            │   │                      (a captive portal), so the batch is not deleted
            │   └── UnaccountedAnswerError  PhyCloud's answer that does not account for
            │                          every event of the batch: kept, retried, halved
            └── EndpointRefusedError  retry it, but slowly and loudly: 401/403 (key),
                                      415 (encoding), other unexpected answers (config)

A batch PhyCloud rejects as bad data (400/422/413) is not an error: the sender splits
it and dead-letters the offending events. No SendError ever drops data.

Whether an error is worth retrying is its type, never a string match.
"""

from __future__ import annotations

# Exit codes of the ``phytrace-edge`` command (docs/operations.md has the table).
EXIT_OK = 0
EXIT_UNHEALTHY = 1  # status: unhealthy; drain: events left; a replay or simulation failed
EXIT_BAD_INPUT = 2  # a bad setting or argument
EXIT_NOT_RUNNING = 3  # status: no service runs on this queue, or there is no queue
EXIT_RUNTIME = 4  # the queue or the network could not be used
EXIT_STAGE_FAILED = 5  # a thread kept failing: let systemd or Docker restart the process
EXIT_INTERRUPTED = 130


class PhytraceError(Exception):
    """Base of every error phytrace-edge raises on purpose."""

    exit_code = EXIT_RUNTIME


class ConfigError(PhytraceError):
    """A setting has a value that is not allowed.

    The message names the setting, the offending value (redacted for secrets) and what
    is allowed, e.g. ``SAMPLE_RATE_HZ='-1': must be a number > 0 and <= 1000``.
    """

    exit_code = EXIT_BAD_INPUT


class StageFailedError(PhytraceError):
    """A thread of the service failed too often in a short time to keep restarting it."""

    exit_code = EXIT_STAGE_FAILED


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


class QueueDamagedError(QueueError):
    """SQLite found the queue file corrupt (or not a database) while using it."""


class SendError(PhytraceError):
    """A batch did not reach PhyCloud this time."""


class TransientSendError(SendError):
    """Worth retrying with backoff; ``retry_after`` is the server's wish, in seconds."""

    def __init__(self, message: str, status: int | None = None, retry_after: float | None = None):
        super().__init__(message)
        self.status = status
        self.retry_after = retry_after


class UnexpectedAnswerError(TransientSendError):
    """A 2xx whose body is not PhyCloud's answer: the batch was not delivered."""


class UnaccountedAnswerError(UnexpectedAnswerError):
    """PhyCloud's answer that does not account for every event of the batch (accepted
    + duplicates + rejected by event_id): nothing of the batch may be deleted on it."""


class EndpointRefusedError(TransientSendError):
    """PhyCloud refuses us for a reason data cannot fix (the key, the encoding, the
    endpoint address): keep the data, back off long, and tell the operator."""
