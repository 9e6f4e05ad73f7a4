"""``export`` and ``import``: the backlog into a hand-carry file, oldest first, for a
robot that has no network, and such a file into a queue that a sender delivers from
(``handcarry.py`` is the file format, MCAP; ``handcarry_phx.py`` reads 0.1.0's).

The events are claimed under leases like a sender's, written, fsynced, and read back;
only when the file under its final name holds every claimed event are they deleted
from the queue (counted as ``exported_total``). Anything else, a full stick, a pulled
stick or a SIGKILL, leaves the events in the queue (a killed export's leases are taken
back by the next process) and at most a ``.part`` file. Run it again for the next
file: each export takes the oldest events still queued.
"""

from __future__ import annotations

import contextlib
import dataclasses
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import cast

from phytrace_edge.errors import QueueError
from phytrace_edge.handcarry import format as handcarry
from phytrace_edge.handcarry import legacy_phx as handcarry_phx
from phytrace_edge.handcarry import reader as handcarry_reader
from phytrace_edge.handcarry.format import (
    CHUNK_BYTES,
    DamagedExport,
    ExportWriter,
    Manifest,
    NotAnExport,
)
from phytrace_edge.queue.records import Batch
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.udm.types import Built, UdmEvent

# a batch is a chunk of the file: zstd compresses a day of events 10% better in 4 MiB
# chunks than in 1 MiB ones (docs/operations.md, "Hand-carry")
BATCH_EVENTS = 2000
BATCH_JSON_BYTES = CHUNK_BYTES


def export_backlog(
    store: QueueStore,
    path: Path,
    source_id: str,
    max_bytes: int,
    progress: Callable[[int], None] = lambda events: None,
) -> Manifest | None:
    """Write the oldest queued events to ``path`` (at most about ``max_bytes``), verify
    the file and delete them from the queue; the file's manifest, or None when the
    queue had nothing to export (no file is written then)."""
    while True:
        written = _write(store, path, source_id, max_bytes, progress)
        if written is None:
            return None
        manifest, batches = written
        if not store.stepped_since(batches[0].claimed_at):
            break
        # the wall clock stepped while the file was written: the queue has repaired the
        # stamps of the events written before it (queue/timekeeping/repair.py), so write them again
        _release(store, batches)
    try:
        _verify(path, manifest)
    except BaseException:
        _release(store, batches)
        raise
    for batch in batches:
        store.ack(batch, exported=True)
    return manifest


def _write(
    store: QueueStore,
    path: Path,
    source_id: str,
    max_bytes: int,
    progress: Callable[[int], None],
) -> tuple[Manifest, list[Batch]] | None:
    """Claim the oldest events and write them to ``path``: (the manifest, the batches
    held), or None when the queue had none."""
    writer = ExportWriter(path, source_id, store.now())
    batches: list[Batch] = []
    try:
        _fill(store, writer, batches, max_bytes, progress)
        if not batches:
            writer.abort()
            return None
        return writer.finish(), batches
    except BaseException:
        writer.abort()
        _release(store, batches)
        raise


def _fill(
    store: QueueStore,
    writer: ExportWriter,
    batches: list[Batch],
    max_bytes: int,
    progress: Callable[[int], None],
) -> None:
    """Claim and write batches until the queue is empty or the next batch might not
    fit; leases are renewed as the file grows (a slow stick). Only the leases of the
    batches written are kept, not their events: a day's backlog does not fit memory."""
    renewed_at, largest = time.monotonic(), 0
    # a batch's JSON at most half the file: even the first batch, which goes in
    # whatever its size (each file takes at least one), fits a small --max-bytes
    batch_json_bytes = min(BATCH_JSON_BYTES, max_bytes // 2)
    # queue time reads as unix seconds on a good clock; this maps it to the wall clock
    # when it did not (a queue that went through a clock step or a reboot without RTC)
    wall_minus_queue = time.time() - store.now()
    while (
        writer.compressed_bytes + 2 * largest + writer.bytes_to_finish <= max_bytes or not batches
    ):
        batch = store.claim_batch(BATCH_EVENTS, batch_json_bytes, important_first=False)
        if batch is None:
            return
        batches.append(dataclasses.replace(batch, events=[]))
        before = writer.compressed_bytes
        for event in batch.events:
            writer.write(event.id, event.json, event.queued_at + wall_minus_queue)
        writer.flush_block()
        largest = max(largest, writer.compressed_bytes - before)
        progress(len(batch.events))
        if time.monotonic() - renewed_at > store.lease_s / 3:
            for held in batches:
                store.renew(held)
            renewed_at = time.monotonic()


def _verify(path: Path, written: Manifest) -> None:
    """Read the finished file back: every CRC, and the manifest's count and checksum
    over the events read match what was written; ``DamagedExport`` otherwise (a
    stick that lies about its writes)."""
    reader = handcarry_reader.open_export(path)
    for _ in reader.events():
        pass
    read = reader.manifest
    if read is None or (read.events, read.sha256) != (written.events, written.sha256):
        raise DamagedExport(str(path), "byte 0", "the file read back does not hold the events")


def _release(store: QueueStore, batches: list[Batch]) -> None:
    """Give the claimed events back to the queue (best effort: the leases run out)."""
    for batch in batches:
        with contextlib.suppress(QueueError):
            store.release(batch)


HandcarryReader = handcarry_reader.ExportReader | handcarry_phx.ExportReader


def open_handcarry(path: Path) -> HandcarryReader:
    """A reader of a hand-carry file of either format, told apart by its first bytes;
    ``NotAnExport`` for anything else."""
    with path.open("rb") as raw:
        magic = raw.read(len(handcarry.MCAP_MAGIC))
    if magic.startswith(handcarry_phx.ZSTD_MAGIC):
        return handcarry_phx.open_export(path)
    if magic == handcarry.MCAP_MAGIC:
        return handcarry_reader.open_export(path)
    raise NotAnExport(str(path), "byte 0", "not a phytrace-edge export (neither MCAP nor .phx)")


def export_chunks(path: Path, size: int) -> Iterator[tuple[list[Built], DamagedExport | None]]:
    """A hand-carry file's events in chunks of ``size``, as the queue takes them, each
    with None, and the last with the damage found (``DamagedExport``) if the file is
    not whole: the events before the first bad record still come, so an import keeps
    what can be kept. The file holds events as a queue held them, without their class:
    they come back periodic (an import sends them at once; nothing thins them)."""
    chunk: list[Built] = []
    try:
        for event in open_handcarry(path).events():
            chunk.append(Built(cast(UdmEvent, event)))
            if len(chunk) >= size:
                yield chunk, None
                chunk = []
    except DamagedExport as damage:
        yield chunk, damage
        return
    yield chunk, None
