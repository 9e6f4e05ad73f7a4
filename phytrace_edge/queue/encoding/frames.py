"""Frames: the events of an outage compressed together, about three times smaller.

A fresh event is a row of its own, compressed alone, ready for the sender to claim in a
live batch. Online it is sent within seconds and never sealed. When events wait longer
than ``SEAL_AFTER_S`` (the link is down, or a replay writes faster than the link
sends), the writer's group commit packs runs of up to ``FRAME_EVENTS`` of them into
one row: their JSON joined by newlines (JSON text never holds a raw newline) and
compressed once. Measured on simulated events (docs/benchmarks.md), 100 events per
frame store in about a third of the bytes of 100 rows.

A frame covers the ids of the rows it was packed from, ``id .. last_id``: rows are only
packed from a run with no other row between them, so no two rows' ranges overlap and
leases (id ranges) keep holding whole rows. An ack deletes only rows wholly within its
lease's range, so a frame sealed after a lease ran out is never deleted by that late
ack (its events are sent again; PhyCloud deduplicates). A frame is claimed, acked,
dropped and expired whole: no frame is decompressed except to seal it and to send it.
"""

from __future__ import annotations

import re
import sqlite3
from collections.abc import Iterator, Sequence

import orjson

from phytrace_edge.queue.encoding.codecs import Codecs
from phytrace_edge.queue.outbound import leases
from phytrace_edge.queue.records import QueuedEvent
from phytrace_edge.queue.storage.rows import FRAMED_COLUMNS, FramedRow, StoredRow

FRAME_EVENTS = 100
SEAL_AFTER_S = 10.0
SEAL_MAX_FRAMES = 20  # per group commit: a long replay backlog is sealed over many
_SCAN_ROWS = 1000

# the builder writes event_id first; anything else is parsed (slower, same answer)
_LEADING_EVENT_ID = re.compile(rb'\{"event_id":"([0-9a-fA-F-]{1,64})"')


def split_frame(json: bytes, count: int) -> list[bytes]:
    """The events of a decoded row: one, or a frame's ``count``."""
    if count == 1:
        return [json]
    events = json.split(b"\n")
    if len(events) != count:
        raise ValueError(f"a frame of {count} events holds {len(events)}")
    return events


def decode_rows(codecs: Codecs, rows: Sequence[StoredRow]) -> list[QueuedEvent]:
    """The events of claimed rows, each row decompressed once. A frame's events get
    the ids ``id + i``: within its range, unique in the batch."""
    events = []
    for row_id, _, count, queued_at, event_id, codec, dict_id, body in rows:
        jsons = split_frame(codecs.decode(codec, dict_id, body), count)
        if count == 1:
            events.append(QueuedEvent(row_id, event_id, jsons[0], queued_at))
        else:
            events.extend(
                QueuedEvent(row_id + i, event_id_of(json), json, queued_at)
                for i, json in enumerate(jsons)
            )
    return events


def event_id_of(json: bytes) -> str:
    """The ``event_id`` of one event's JSON (empty when it has none)."""
    match = _LEADING_EVENT_ID.match(json)
    if match is not None:
        return match.group(1).decode()
    value = orjson.loads(json).get("event_id", "")
    return value if isinstance(value, str) else str(value)


class Sealer:
    """Packs old single-event rows into frames, in the writer's transaction. Remembers
    how far it has looked, so a backlog of frames is not scanned again at every put."""

    def __init__(self, codecs: Codecs, frame_events: int = FRAME_EVENTS) -> None:
        self._codecs = codecs
        self.frame_events = frame_events
        self.sealed_below = 0  # every row under this id is a frame, leased, or checked

    def seal(self, cursor: sqlite3.Cursor, now: float) -> int:
        """Seal up to ``SEAL_MAX_FRAMES`` frames of rows queued before
        ``now - SEAL_AFTER_S`` that no lease covers; the number of frames made. Frames
        of one event are no frames: ``frame_events=1`` turns sealing off."""
        if self.frame_events < 2:
            return 0
        made = 0
        for run in self._runs(cursor, now, now - SEAL_AFTER_S):
            if made >= SEAL_MAX_FRAMES:
                return made
            self._pack(cursor, run)
            made += 1
        return made

    def _runs(self, cursor: sqlite3.Cursor, now: float, cutoff: float) -> Iterator[list[int]]:
        """Ids of runs of ``frame_events`` consecutive single rows no lease covers, all
        old enough (a run never crosses a lease)."""
        run: list[int] = []
        stretch = None
        columns = "id, last_id, count, important, queued_at"
        for chunk in leases.unleased(cursor, now, columns, _SCAN_ROWS, from_id=self.sealed_below):
            if chunk.high != stretch:  # another stretch between leases: another run
                stretch, run = chunk.high, []
            for row_id, last_id, count, important, queued_at in chunk.rows:
                if queued_at >= cutoff:
                    return  # ids grow with time: the rest is fresh
                if count > 1 or important:  # a frame, or an event that stays alone
                    run = []
                    self.sealed_below = last_id + 1
                    continue
                run.append(row_id)
                if len(run) == self.frame_events:
                    yield run
                    self.sealed_below = run[-1] + 1
                    run = []

    def _pack(self, cursor: sqlite3.Cursor, ids: list[int]) -> None:
        rows = [
            FramedRow._make(row)
            for row in cursor.execute(
                f"SELECT {FRAMED_COLUMNS} FROM events WHERE id BETWEEN ? AND ? ORDER BY id",
                (ids[0], ids[-1]),
            )
        ]
        events = [self._codecs.decode(row.codec, row.dict_id, row.body) for row in rows]
        encoded = self._codecs.encode(b"\n".join(events))
        freed = sum(len(row.body) for row in rows) - len(encoded.body)
        cursor.execute("DELETE FROM events WHERE id BETWEEN ? AND ?", (ids[0], ids[-1]))
        cursor.execute(
            "INSERT INTO events(id, last_id, count, queued_at, newest_at, event_id, codec, "
            "dict_id, json_size, body) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
            (
                ids[0],
                ids[-1],
                len(rows),
                rows[0].queued_at,
                rows[-1].queued_at,  # newest_at: the frame expires with its newest event
                rows[0].event_id,
                encoded.codec,
                encoded.dict_id,
                sum(len(event) for event in events),
                encoded.body,
            ),
        )
        cursor.execute(
            "UPDATE counters SET value = value - ? WHERE name = 'stored_bytes'", (freed,)
        )
