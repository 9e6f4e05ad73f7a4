"""Dead letters: events PhyCloud rejected for good, kept for an operator to inspect.

The workflow: ``list`` what is there and why, ``export`` it as JSON Lines to look at
or hand to PhyCloud support, then ``requeue`` (after PhyCloud or the robot was fixed:
the events go to the back of the queue and are sent again) or ``purge``. A requeue
never drops queued events to make room: what does not fit under the caps stays here.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import IO, Any

import orjson

from phytrace_edge.queue.encoding.codecs import Codecs
from phytrace_edge.queue.records import DeadLetter, DeadLetterRow, QueuedEvent
from phytrace_edge.queue.space.caps import Caps
from phytrace_edge.queue.storage.database import Database, bump_counters
from phytrace_edge.queue.storage.rows import NewRow, insert_rows

_COLUMNS = "id, event_id, queued_at, dead_at, reason, status_code, response, json_size"


@dataclass(frozen=True)
class DeadLetterInfo:
    """One dead letter without its body."""

    id: int
    event_id: str
    queued_at: float
    dead_at: float
    reason: str
    status_code: int | None
    response: str | None
    json_size: int


class DeadLetterBox:
    """List, export, requeue and purge the dead letters of one queue
    (``QueueStore.dead_letters``)."""

    def __init__(
        self, db: Database, codecs: Codecs, caps: Caps, clock: Callable[[], float]
    ) -> None:
        self._db = db
        self._codecs = codecs
        self._caps = caps
        self._clock = clock

    def count(self) -> int:
        return self._db.counter("dead_letters")

    def list(self, limit: int = 100, offset: int = 0) -> list[DeadLetterInfo]:
        """Oldest first."""
        rows = self._db.read(
            f"SELECT {_COLUMNS} FROM dead_letters ORDER BY id LIMIT ? OFFSET ?", (limit, offset)
        )
        return [DeadLetterInfo(*row) for row in rows]

    def iter_events(self, chunk: int = 500) -> Iterator[tuple[DeadLetterInfo, dict[str, Any]]]:
        """Every dead letter with its decoded event, oldest first, a chunk at a time."""
        after = 0
        while True:
            rows = self._db.read(
                f"SELECT {_COLUMNS}, codec, dict_id, body FROM dead_letters "
                "WHERE id > ? ORDER BY id LIMIT ?",
                (after, chunk),
            )
            if not rows:
                return
            for *info, codec, dict_id, body in rows:
                event = orjson.loads(self._codecs.decode(codec, dict_id, body))
                yield DeadLetterInfo(*info), event
            after = rows[-1][0]

    def export(self, out: IO[bytes]) -> int:
        """Write JSON Lines ``{"dead_letter": {...}, "event": {...}}``; the count."""
        written = 0
        for info, event in self.iter_events():
            line = {"dead_letter": vars(info), "event": event}
            out.write(orjson.dumps(line) + b"\n")
            written += 1
        return written

    def requeue(self, ids: Sequence[int] | None = None) -> int:
        """Move dead letters (all, or ``ids``), oldest first, back to the end of the
        queue, as many as fit under the caps; the number moved."""
        where, params = _selection(ids)
        now = self._clock()
        with self._db.transaction() as cursor:
            rows = cursor.execute(
                # requeued by hand: important, never thinned
                f"SELECT id, event_id, 1, ?, codec, dict_id, json_size, body FROM dead_letters "
                f"{where} ORDER BY id",
                (now, *params),
            ).fetchall()
            rows = rows[: self._caps.fitting(cursor, [len(row[-1]) for row in rows])]
            insert_rows(
                cursor,
                [NewRow._make(row[1:]) for row in rows],
                requeued_total=len(rows),
                dead_letters=-len(rows),
            )
            cursor.executemany("DELETE FROM dead_letters WHERE id = ?", [row[:1] for row in rows])
        return len(rows)

    def purge(self, ids: Sequence[int] | None = None, before: float | None = None) -> int:
        """Delete dead letters: all, ``ids``, or those that died before ``before``."""
        where, selected = _selection(ids)
        params: tuple[float, ...] = selected
        if before is not None:
            where += (" AND" if where else "WHERE") + " dead_at < ?"
            params = (*selected, before)
        with self._db.transaction() as cursor:
            purged = int(cursor.execute(f"DELETE FROM dead_letters {where}", params).rowcount)
            bump_counters(cursor, dead_letters=-purged)
        return purged


def dead_letter_row(codecs: Codecs, event: QueuedEvent, dead: DeadLetter) -> DeadLetterRow:
    """A rejected event of a batch, encoded on its own to be kept as a dead letter."""
    encoded = codecs.encode(event.json)
    return DeadLetterRow(
        dead.queue_id,
        event.event_id,
        event.queued_at,
        dead.reason,
        dead.status_code,
        dead.response,
        encoded.codec,
        encoded.dict_id,
        len(event.json),
        encoded.body,
    )


def _selection(ids: Sequence[int] | None) -> tuple[str, tuple[int, ...]]:
    if ids is None:
        return "", ()
    marks = ",".join("?" * len(ids)) or "NULL"
    return f"WHERE id IN ({marks})", tuple(ids)
