"""Fixtures of the unit tests."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from phytrace_edge.queue.store import QueueStore
from tests.unit.queue_fixtures import Clock, store_opener


@pytest.fixture
def open_store(tmp_path: Path, clock: Clock) -> Iterator[Callable[..., QueueStore]]:
    """Queue stores on the test module's ``clock``, which must be a ``queue_fixtures.Clock``
    (``tests/conftest.py``'s ``clock`` is the builder's)."""
    yield from store_opener(tmp_path, clock)
