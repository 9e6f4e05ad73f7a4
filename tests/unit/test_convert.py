"""Shared conversions: hostile numbers, quaternions (REP-103), headings, stamps."""

from __future__ import annotations

import math
from types import SimpleNamespace as NS

import numpy as np
import pytest

from phytrace_edge.ingest.convert import (
    compact,
    compass_heading_deg,
    finite,
    integer,
    quaternion_to_rpy_deg,
    stamp_ns,
    text,
)


@pytest.mark.parametrize(
    ("value", "expected"),
    [
        (1.5, 1.5),
        (3, 3.0),
        (np.float32(2.5), 2.5),
        (math.nan, None),
        (-math.inf, None),
        (True, None),
        ("1.0", None),
        (None, None),
    ],
)
def test_finite(value: object, expected: float | None) -> None:
    assert finite(value) == expected


@pytest.mark.parametrize(
    ("value", "expected"),
    [
        (b"\x02", 2),
        (2, 2),
        (np.uint8(3), 3),
        (b"", None),
        (b"\x01\x02", None),
        (False, None),
        (1.0, None),
    ],
)
def test_integer_accepts_rclpy_bytes_and_ints(value: object, expected: int | None) -> None:
    assert integer(value) == expected


@pytest.mark.parametrize(
    ("q", "rpy"),
    [
        ((0, 0, 0, 1), (0, 0, 0)),
        ((0, 0, math.sin(math.pi / 4), math.cos(math.pi / 4)), (0, 0, 90)),
        ((0, 0, 1, 0), (0, 0, -180)),  # yaw 180 folds to -180
        ((math.sin(math.pi / 8), 0, 0, math.cos(math.pi / 8)), (45, 0, 0)),
        ((0, math.sin(-math.pi / 12), 0, math.cos(-math.pi / 12)), (0, -30, 0)),
        ((0, 0, 2 * math.sin(math.pi / 4), 2 * math.cos(math.pi / 4)), (0, 0, 90)),  # unnormalised
    ],
)
def test_quaternion_to_rpy(q: tuple[float, ...], rpy: tuple[float, ...]) -> None:
    got = quaternion_to_rpy_deg(NS(x=q[0], y=q[1], z=q[2], w=q[3]))
    assert got == pytest.approx(rpy, abs=1e-9)


@pytest.mark.parametrize("q", [(0, 0, 0, 0), (math.nan, 0, 0, 1), (0, 0, math.inf, 1)])
def test_invalid_quaternion_has_no_orientation(q: tuple[float, ...]) -> None:
    assert quaternion_to_rpy_deg(NS(x=q[0], y=q[1], z=q[2], w=q[3])) is None


@pytest.mark.parametrize(
    ("enu_yaw", "heading"), [(0, 90), (90, 0), (180, 270), (-90, 180), (45.2, 44.8), (-180, 270)]
)
def test_compass_heading_from_enu_yaw(enu_yaw: float, heading: float) -> None:
    assert compass_heading_deg(enu_yaw) == pytest.approx(heading)


def test_stamp_zero_is_no_stamp_not_1970() -> None:
    assert stamp_ns(NS(stamp=NS(sec=0, nanosec=0))) is None
    assert stamp_ns(NS(stamp=NS(sec=12, nanosec=5))) == 12_000_000_005
    assert stamp_ns(None) is None


def test_text_cuts_and_rejects() -> None:
    assert text("a" * 300) == "a" * 256
    assert text(b"lidar") == "lidar"
    assert text(5) is None


def test_compact_drops_none_and_empty_dicts_but_keeps_empty_lists() -> None:
    assert compact({"a": None, "b": {}, "c": {"d": None}, "e": [], "f": 0}) == {"e": [], "f": 0}
