"""The id-range arithmetic of leases (pure)."""

from __future__ import annotations

import pytest

from phytrace_edge.queue.outbound.leases import gaps


@pytest.mark.parametrize(
    ("span", "ranges", "expected"),
    [
        ((1, 10), [], [(1, 10)]),
        ((1, 10), [(3, 4), (7, 8)], [(1, 2), (5, 6), (9, 10)]),
        ((1, 10), [(0, 2), (2, 5), (4, 6)], [(7, 10)]),  # overlapping, from before the span
        ((1, 10), [(1, 10)], []),
        ((5, 10), [(1, 3), (12, 20)], [(5, 10)]),  # wholly outside
        ((1, 10), [(8, 30)], [(1, 7)]),
    ],
)
def test_gaps_are_what_no_range_covers(
    span: tuple[int, int], ranges: list[tuple[int, int]], expected: list[tuple[int, int]]
) -> None:
    assert gaps(span, ranges) == expected
