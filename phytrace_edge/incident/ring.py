"""The rolling window: every reading of the window topics, oldest first, bounded in
time and in bytes.

A reading is kept as its JSON (orjson), not as the handler's dict: JSON is what an
incident ships, it is several times smaller in memory than nested dicts, and its
length is an honest measure for INCIDENT_BUFFER_MAX_BYTES. Each sample counts its
JSON and ``SAMPLE_OVERHEAD_BYTES`` for the Python objects that hold it.

Samples older than the horizon (INCIDENT_BEFORE_S, or the open incident's start) leave
quietly; samples the byte bound pushes out while still inside it are counted
(``dropped``), by topic, so that an incident can say what it lacks.
"""

from __future__ import annotations

from collections import Counter, deque
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any

import orjson

SAMPLE_OVERHEAD_BYTES = 240  # the Kept, its bytes object and the deque's slot (measured)


@dataclass(frozen=True)
class Kept:
    """One reading of one topic: when it was received on the input's timeline (``at_s``,
    monotonic: the window's arithmetic; its wall-clock stamp is made when an incident
    closes, ``parts.Sample``) and its JSON."""

    topic: str
    at_s: float
    json: bytes

    @property
    def size(self) -> int:
        return len(self.json) + SAMPLE_OVERHEAD_BYTES


class WindowRing:
    """Samples in time order; ``add`` keeps them within ``max_bytes``."""

    def __init__(self, max_bytes: int) -> None:
        self.max_bytes = max_bytes
        self._samples: deque[Kept] = deque()
        self.bytes = 0
        self.dropped: Counter[str] = Counter()  # by topic: pushed out by the byte bound

    def __len__(self) -> int:
        return len(self._samples)

    def add(self, topic: str, reading: Mapping[str, Any], at_s: float) -> tuple[Kept, ...]:
        """Keep ``reading``; beyond the byte bound the oldest samples go, counted, and
        are returned (usually none)."""
        # a copy: the bytes orjson returns keep its whole working buffer (4 KiB) alive
        # behind a few hundred bytes of JSON, which made a full 16 MiB ring 192 MiB of RSS
        # (docs/benchmarks.md, "Incident window")
        sample = Kept(topic, at_s, bytes(memoryview(orjson.dumps(reading))))
        self._samples.append(sample)
        self.bytes += sample.size
        if self.bytes <= self.max_bytes:
            return ()
        evicted = []
        while self.bytes > self.max_bytes and self._samples:
            oldest = self._samples.popleft()
            self.bytes -= oldest.size
            self.dropped[oldest.topic] += 1
            evicted.append(oldest)
        return tuple(evicted)

    def forget_before(self, horizon_s: float) -> None:
        """Let the samples received before ``horizon_s`` go (they left the window)."""
        while self._samples and self._samples[0].at_s < horizon_s:
            self.bytes -= self._samples.popleft().size

    def between(self, start_s: float, end_s: float) -> Iterator[Kept]:
        """The samples received in [start_s, end_s], oldest first."""
        return (s for s in self._samples if start_s <= s.at_s <= end_s)
