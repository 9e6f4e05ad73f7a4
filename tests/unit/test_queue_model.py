"""Model-based test of the queue's whole life, in the manner of Vector's buffer model
tests: random sequences of put (important and periodic events) / claim from either lane
/ ack (with dead letters) / release / requeue / clock steps / TTL expiry / reopen after
a crash, against the real store on a real file and a trivial model, under small byte
and event caps with every on-full policy (thinning included).

Invariants: the store holds exactly the events the model says, in order; every event
ever put is in exactly one place (queued, delivered, thinned, dropped by reason,
expired or dead-lettered) and each is counted; a full queue drops only what its policy
allows; an important event is never thinned, and never dropped while a periodic one
that could have gone instead is left.
"""

from __future__ import annotations

import base64
import itertools
import random
import shutil
import sqlite3
import tempfile
import uuid
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

from hypothesis import event, settings
from hypothesis import strategies as st
from hypothesis.stateful import (
    Bundle,
    RuleBasedStateMachine,
    consumes,
    initialize,
    invariant,
    precondition,
    rule,
)

from phytrace_edge.queue.encoding.frames import SEAL_AFTER_S, decode_rows
from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.outbound.claims import BAND_S
from phytrace_edge.queue.records import Batch, DeadLetter
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.units import GIB, KIB, MIB
from tests.queue_events import put_events

LEASE_S = 10.0
FRAME_EVENTS = 3  # small frames, so that runs of a few dozen steps make many
TTL_S = 100.0


def seq_of(event_id: str) -> int:
    return uuid.UUID(event_id).int


@dataclass
class Claim:
    batch: Batch
    seqs: list[int]
    rows: set[tuple[int, int]]  # (seq, incarnation): a requeued event is a new row
    expires_at: float


class QueueAccounting(RuleBasedStateMachine):
    claims = Bundle("claims")

    def __init__(self) -> None:
        super().__init__()
        self.dir = Path(tempfile.mkdtemp(prefix="queue-accounting-"))
        self.now = 1_000_000.0
        self.next_seq = 1
        self.queue: list[int] = []  # the model: seqs queued, oldest first
        self.queued_at: dict[int, float] = {}
        self.open_claims: list[Claim] = []
        self.dead: list[int] = []
        self.fate: Counter[str] = Counter()  # acked, drop:<reason>
        self.requeued = 0
        self.important: set[int] = set()
        self.incarnation: Counter[int] = Counter()
        self.generation = 0

    @initialize(
        on_full=st.sampled_from(["thin", "thin", "drop_oldest", "drop_newest"]),
        max_events=st.sampled_from([None, 8, 25]),
        small_bytes=st.booleans(),
    )
    def open_store(self, on_full: str, max_events: int | None, small_bytes: bool) -> None:
        self.limits = QueueLimits(
            max_bytes=160 * KIB if small_bytes else GIB,
            max_events=max_events,
            on_full=on_full,
            ttl_s=TTL_S,
        )
        self.store = self._open(self.dir / "q0.db")

    def _open(self, path: Path) -> QueueStore:
        # durability across crashes is what the copies test; fsyncs would only slow it
        return QueueStore.open(
            path,
            limits=self.limits,
            sync="normal",
            clock=lambda: self.now,
            lease_s=LEASE_S,
            frame_events=FRAME_EVENTS,
        )

    # ------------------------------------------------------------------ the model

    def leased(self) -> set[int]:
        return {
            s
            for c in self.open_claims
            if c.expires_at > self.now
            for s in c.seqs
            if (s, self.incarnation[s]) in c.rows
        }

    def stored_spans(self) -> list[tuple[int, int, list[int]]]:
        """(first id, last id, seqs) of each row of the queue, oldest first."""
        rows = self.store._db.read(
            "SELECT id, last_id, count, queued_at, event_id, codec, dict_id, body "
            "FROM events ORDER BY id"
        )
        spans = []
        for row in rows:
            seqs = [seq_of(e.event_id) for e in decode_rows(self.store.codecs, [row])]
            spans.append((row[0], row[1], seqs))
        for (_, last, _), (first, _, _) in itertools.pairwise(spans):
            assert last < first, "rows' id ranges never overlap"
        return spans

    def stored_rows(self) -> list[list[int]]:
        """The seqs of each row of the queue, oldest first: one, or a frame's."""
        return [seqs for _, _, seqs in self.stored_spans()]

    def stored_seqs(self) -> list[int]:
        return [s for row in self.stored_rows() for s in row]

    # ------------------------------------------------------------------ rules

    @rule(count=st.integers(1, 12), pad=st.integers(100, 1500), mask=st.integers(0, 4095))
    def put(self, count: int, pad: int, mask: int) -> None:
        seqs = list(range(self.next_seq, self.next_seq + count))
        classes = [bool(mask >> i & 1) and bool(mask >> (i + 1) & 1) for i in range(count)]
        self.next_seq += count
        events = [
            {
                "event_id": str(uuid.UUID(int=s)),
                "pad": base64.b64encode(random.Random(s).randbytes(pad)).decode()[:pad],
            }
            for s in seqs
        ]
        leased, before = self.leased(), list(self.queue)
        drops_before = self.store.stats().drops
        result = put_events(self.store, events, classes)
        self.important.update(s for s, important in zip(seqs, classes, strict=True) if important)
        assert result.accepted + result.dropped == count

        stored = self.stored_seqs()
        removed = [s for s in before if s not in set(stored)]
        kept_new = [s for s in seqs if s in set(stored)]
        assert kept_new == seqs[: len(kept_new)], "only the newest incoming are refused"
        assert len(kept_new) == result.accepted
        assert not set(removed) & leased, "events being sent are never dropped"
        if self.limits.on_full == "drop_newest":
            assert removed == [], "drop_newest keeps what is queued"
        elif self.limits.on_full == "thin":
            kept_old = [s for s in before if s not in set(removed) and s not in leased]
            if set(removed) & self.important:
                assert all(s in self.important for s in kept_old), (
                    "an important event goes only when no periodic one is left"
                )
        else:
            unleased = [s for s in before if s not in leased]
            assert removed == unleased[: len(removed)], "drop_oldest drops the oldest"
            if kept_new != seqs:
                assert removed == unleased, "new events are refused only when nothing is left"
        if self.limits.max_events is not None:
            assert len(stored) <= self.limits.max_events

        dropped_now = len(removed) + count - len(kept_new)
        drops_after = self.store.stats().drops
        reasons = ("cap_bytes", "cap_events", "thinned")
        by_cap = sum(drops_after.get(r, 0) - drops_before.get(r, 0) for r in reasons)
        assert by_cap == dropped_now
        thinned = drops_after.get("thinned", 0) - drops_before.get("thinned", 0)
        assert thinned <= len([s for s in removed if s not in self.important])
        if thinned:
            event("history thinned")
        for reason in reasons:
            self.fate[f"drop:{reason}"] += drops_after.get(reason, 0) - drops_before.get(reason, 0)
        self.queue = [s for s in before if s not in set(removed)] + kept_new
        for s in kept_new:
            self.queued_at[s] = self.now

    def live_ranges(self) -> list[tuple[int, int]]:
        """The id ranges under live leases (a lease may cover ids whose rows are gone)."""
        return [r for c in self.open_claims if c.expires_at > self.now for r in c.batch.ranges]

    def runs(self, spans: list[tuple[int, int, list[int]]]) -> list[list[list[int]]]:
        """The unleased rows of these spans (in the order given) in runs that no live
        lease range interrupts, each row as its seqs."""
        leased, runs, run = self.live_ranges(), [], []
        previous: tuple[int, int] | None = None
        for first, last, seqs in spans:
            low, high = (
                (first, last)
                if previous is None
                else (min(previous[1] + 1, first), max(previous[0] - 1, last))
            )
            if any(lo <= high and low <= hi for lo, hi in leased):
                if run:
                    runs.append(run)
                run = []
                if any(lo <= last and first <= hi for lo, hi in leased):
                    previous = None
                    continue
            run.append(seqs)
            previous = (first, last)
        return [*runs, run] if run else runs

    @rule(target=claims, limit=st.integers(1, 10), important_first=st.booleans())
    def claim(self, limit: int, important_first: bool) -> Claim | None:
        """The backfill: the important events of the oldest hour first, else the oldest
        whole rows up to a leased range."""
        runs = self.runs(self.stored_spans())
        expected: list[int] = []
        if important_first and runs:
            band_end = self.queued_at[runs[0][0][0]] + BAND_S
            expected = [
                row[0]
                for run in runs
                for row in run
                if row[0] in self.important and self.queued_at[row[0]] < band_end
            ][:limit]
        for row in runs[0] if runs and not expected else []:
            if expected and len(expected) + len(row) > limit:
                break
            expected += row
        batch = self.store.claim_batch(limit, 64 * MIB, important_first=important_first)
        return self._claimed(batch, expected)

    @rule(target=claims, limit=st.integers(1, 10), back_s=st.sampled_from([0.0, 5.0, 60.0]))
    def claim_live(self, limit: int, back_s: float) -> Claim | None:
        """The live lane: the newest whole rows put since ``since``, from the newest run
        of unleased rows."""
        since = self.now - back_s
        runs = self.runs(list(reversed(self.stored_spans())))
        taken: list[list[int]] = []
        for row in runs[0] if runs else []:
            if self.queued_at[row[0]] < since:
                break
            if taken and sum(map(len, taken)) + len(row) > limit:
                break
            taken.append(row)
        expected = [s for row in reversed(taken) for s in row]
        event("live lane took events" if expected else "live lane empty")
        return self._claimed(self.store.claim_live(limit, 64 * MIB, since), expected)

    def _claimed(self, batch: Batch | None, expected: list[int]) -> Claim | None:
        got = [] if batch is None else [seq_of(e.event_id) for e in batch.events]
        assert got == expected
        if batch is None:
            return None
        claim = Claim(batch, got, {(q, self.incarnation[q]) for q in got}, self.now + LEASE_S)
        self.open_claims.append(claim)
        return claim

    @rule(claim=consumes(claims), reject=st.lists(st.integers(0, 9), max_size=3, unique=True))
    def ack(self, claim: Claim | None, reject: list[int]) -> None:
        if claim is None:
            return
        events, batch = claim.batch.events, claim.batch
        # what the ack deletes: rows wholly in its range (a frame sealed after its
        # lease ran out may reach past it, and stays to be sent again)
        within = {
            s
            for first, last, seqs in self.stored_spans()
            if any(low <= first and last <= high for low, high in batch.ranges)
            for s in seqs
        }
        dead = [DeadLetter(events[i].id, "rejected: test") for i in reject if i < len(events)]
        self.store.ack(batch, dead)
        still = {q for q in self.queue if (q, self.incarnation[q]) in claim.rows and q in within}
        dead_seqs = [seq_of(events[i].event_id) for i in reject if i < len(events)]
        dead_seqs = [s for s in dead_seqs if s in still]
        self.dead += dead_seqs
        self.fate["drop:rejected"] += len(dead_seqs)
        self.fate["acked"] += len([s for s in claim.seqs if s in still]) - len(dead_seqs)
        self.queue = [s for s in self.queue if s not in still]
        self.open_claims.remove(claim)

    @rule(claim=consumes(claims))
    def release(self, claim: Claim | None) -> None:
        if claim is None:
            return
        self.store.release(claim.batch)
        self.open_claims.remove(claim)

    @precondition(lambda self: self.dead)
    @rule()
    def requeue_dead_letters(self) -> None:
        moved = self.store.dead_letters.requeue()
        if self.limits.max_events is not None:
            assert moved <= max(0, self.limits.max_events - len(self.queue))
        if moved < len(self.dead):
            depth, cap = self.store.stats().depth, self.limits.max_events
            at_event_cap = cap is not None and depth >= cap
            assert at_event_cap or self.limits.max_bytes < GIB, "stops short only at a cap"
        for s in self.dead[:moved]:
            self.queued_at[s] = self.now
            self.incarnation[s] += 1
            self.important.add(s)  # requeued by hand: never thinned
        self.queue += self.dead[:moved]
        self.requeued += moved
        self.dead = self.dead[moved:]

    @rule(seconds=st.sampled_from([1.0, LEASE_S + 1, TTL_S / 2]))
    def time_passes(self, seconds: float) -> None:
        self.now += seconds

    @rule()
    def expire(self) -> None:
        leased, cutoff = self.leased(), self.now - TTL_S
        old = [  # a frame goes when its newest event is past the TTL
            s
            for row in self.stored_rows()
            if max(self.queued_at[q] for q in row) < cutoff and not set(row) & leased
            for s in row
        ]
        assert self.store.expire() == len(old)
        self.fate["drop:ttl"] += len(old)
        self.queue = [s for s in self.queue if s not in set(old)]

    @rule(mid_transaction=st.booleans())
    def crash_and_reopen(self, mid_transaction: bool) -> None:
        """Power is cut: the files as they are on disk now become the queue. Mid
        transaction, an uncommitted put is in the WAL of the copy, and must vanish. The
        process that held the claims is gone: the new store takes them back."""
        self.generation += 1
        copy = self.dir / f"q{self.generation}.db"
        path = self.store.path
        if mid_transaction:
            # another writer's transaction, big enough that its pages spill into the WAL
            # before COMMIT: the copy holds uncommitted frames that recovery must ignore
            writer = sqlite3.connect(path, isolation_level=None, timeout=5)
            try:
                writer.execute("PRAGMA cache_size = 1")
                writer.execute("BEGIN IMMEDIATE")
                writer.executemany(
                    "INSERT INTO events(id, last_id, event_id, queued_at, codec, json_size, body) "
                    "VALUES (?, ?, ?, ?, 0, 2, ?)",
                    [
                        (i, i, str(uuid.UUID(int=2**100 + i)), self.now, b"x" * 4000)
                        for i in range(2**40, 2**40 + 50)
                    ],
                )
                self._copy(path, copy)
                writer.execute("ROLLBACK")
            finally:
                writer.close()
        else:
            self._copy(path, copy)
        self.store.close()
        self.store = self._open(copy)
        for claim in self.open_claims:  # their owner died: its claims are taken back at once
            claim.expires_at = float("-inf")

    @staticmethod
    def _copy(path: Path, copy: Path) -> None:
        for suffix in ("", "-wal"):
            source = Path(f"{path}{suffix}")
            if source.exists():
                shutil.copyfile(source, f"{copy}{suffix}")

    # ------------------------------------------------------------------ invariants

    @invariant()
    def the_store_holds_what_the_model_says(self) -> None:
        if not hasattr(self, "store"):
            return
        rows = self.stored_rows()
        assert [s for row in rows for s in row] == self.queue
        event("frames in the queue" if any(len(row) > 1 for row in rows) else "no frames")
        for row in (row for row in rows if len(row) > 1):
            assert len(row) <= FRAME_EVENTS
            assert not set(row) & self.important, "an important event is never in a frame"
            newest = max(self.queued_at[s] for s in row)
            assert newest <= self.now - SEAL_AFTER_S, "fresh events are never sealed"
            live = (c for c in self.open_claims if c.expires_at > self.now)
            for claim in live:  # a live lease holds a frame whole, or none of it
                held = set(row) & set(claim.seqs)
                assert not held or held == set(row), "a lease splits a frame"

    @invariant()
    def every_event_is_in_exactly_one_place_and_counted(self) -> None:
        if not hasattr(self, "store"):
            return
        stats = self.store.stats()
        drops = stats.drops
        assert stats.depth == len(self.queue)
        assert stats.dead_letters == len(self.dead) == self.store.dead_letters.count()
        assert stats.acked_total == self.fate["acked"]
        for reason in ("cap_bytes", "cap_events", "thinned", "ttl", "rejected"):
            assert drops.get(reason, 0) == self.fate[f"drop:{reason}"], reason
        put = self.next_seq - 1
        assert stats.queued_total == put
        accounted = (
            len(self.queue)
            + self.fate["acked"]
            + sum(n for k, n in self.fate.items() if k.startswith("drop:"))
            - self.requeued
        )
        assert accounted == put, "every event put is in exactly one place"

    def teardown(self) -> None:
        if hasattr(self, "store"):
            self.store.close()
        shutil.rmtree(self.dir, ignore_errors=True)


TestQueueAccounting = QueueAccounting.TestCase
TestQueueAccounting.settings = settings(max_examples=150, stateful_step_count=40, deadline=None)
