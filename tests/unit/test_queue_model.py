"""Model-based test: random put / claim / ack / release / reopen sequences against the
real store and a plain list, which must agree on every step."""

from __future__ import annotations

import shutil
import tempfile
import uuid
from pathlib import Path

import orjson
from hypothesis import settings
from hypothesis import strategies as st
from hypothesis.stateful import Bundle, RuleBasedStateMachine, consumes, invariant, rule

from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.records import Batch
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.units import GIB, MIB


class QueueMachine(RuleBasedStateMachine):
    batches = Bundle("batches")

    def __init__(self) -> None:
        super().__init__()
        self.dir = Path(tempfile.mkdtemp(prefix="queue-model-"))
        self.store = self._open()
        self.model: list[int] = []  # seqs in the queue, oldest first
        self.leased: set[int] = set()
        self.next_seq = 0

    def _open(self) -> QueueStore:
        return QueueStore.open(
            self.dir / "q.db", limits=QueueLimits(max_bytes=GIB), compression="zstd", lease_s=3600
        )

    @rule(count=st.integers(1, 20))
    def put(self, count: int) -> None:
        seqs = list(range(self.next_seq, self.next_seq + count))
        self.next_seq += count
        events = [{"event_id": str(uuid.UUID(int=s)), "seq": s} for s in seqs]
        assert self.store.put_many(events).accepted == count
        self.model.extend(seqs)

    @rule(target=batches, limit=st.integers(1, 15))
    def claim(self, limit: int) -> Batch | None:
        # the model: the oldest run of unleased events, stopping at a leased one
        free = [i for i, s in enumerate(self.model) if s not in self.leased]
        expected: list[int] = []
        if free:
            for seq in self.model[free[0] :]:
                if seq in self.leased or len(expected) == limit:
                    break
                expected.append(seq)
        batch = self.store.claim_batch(limit, 64 * MIB)
        got = [] if batch is None else [orjson.loads(e.json)["seq"] for e in batch.events]
        assert got == expected
        self.leased.update(got)
        return batch

    @rule(batch=consumes(batches))
    def ack(self, batch: Batch | None) -> None:
        if batch is None:
            return
        self.store.ack(batch)
        seqs = {orjson.loads(e.json)["seq"] for e in batch.events}
        self.model = [s for s in self.model if s not in seqs]
        self.leased -= seqs

    @rule(batch=consumes(batches))
    def release(self, batch: Batch | None) -> None:
        if batch is None:
            return
        self.store.release(batch)
        self.leased -= {orjson.loads(e.json)["seq"] for e in batch.events}

    @rule()
    def reopen(self) -> None:
        self.store.close()
        self.store = self._open()

    @invariant()
    def counters_agree(self) -> None:
        stats = self.store.stats()
        assert stats.depth == len(self.model)
        assert stats.queued_total == self.next_seq

    def teardown(self) -> None:
        self.store.close()
        shutil.rmtree(self.dir, ignore_errors=True)


TestQueueModel = QueueMachine.TestCase
TestQueueModel.settings = settings(max_examples=40, stateful_step_count=30, deadline=None)
