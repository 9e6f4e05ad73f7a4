"""Shared conversions: hostile numbers, quaternions (REP-103), headings, stamps."""

from __future__ import annotations

import math
from types import SimpleNamespace as NS

import numpy as np
import pytest

from phytrace_edge.ingest.convert import (
    LATLON,
    MM,
    PERCENT,
    compass_heading_deg,
    degrees,
    f32,
    f32_all,
    finite,
    integer,
    present,
    quaternion_to_rpy_deg,
    quaternion_to_yaw_deg,
    rounded,
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


def test_present_drops_none_and_empty_dicts_but_keeps_empty_lists_and_zeros() -> None:
    assert present(a=None, b={}, e=[], f=0, g=0.0) == {"e": [], "f": 0, "g": 0.0}


def float32(value: float) -> float:
    """``value`` as a float32 sensor reports it (what rclpy hands over as a float)."""
    return float(np.float32(value))


@pytest.mark.parametrize(
    ("source", "written"),
    [
        (0.12, 0.12),  # LaserScan.range_min 0.12f, not 0.11999999731779099
        (24.4283390045166, 24.428339),  # BatteryState.voltage
        (3.7, 3.7),
        (30.0, 30.0),
        (-1.5, -1.5),
        (1e-7, 1e-7),
        (16777217.0, 16777216.0),  # float32 holds 24 bits
    ],
)
def test_float32_fields_are_written_at_their_real_precision(source: float, written: float) -> None:
    value = float32(source)
    assert f32(value) == written
    assert repr(f32(value)) == repr(written)  # the JSON text, too
    assert f32_all([value, value]) == [written, written]
    assert np.float32(f32(value)) == np.float32(value)  # and it reads back as the same float32


def test_f32_writes_what_numpy_prints_for_a_float32() -> None:
    """The bridge does not import numpy; numpy's float32 printing is the reference."""
    import random

    rng = random.Random(7)
    values = [rng.uniform(-1e3, 1e3) for _ in range(3000)]
    values += [10.0 ** rng.uniform(-40, 38) for _ in range(3000)]  # subnormals to the top
    values += [3.4028234663852886e38, 1.401298464324817e-45, 0.1, 100.0, -0.0]
    for value in values:
        assert f32(value) == float(str(np.float32(value))), value


def test_f32_all_takes_fields_and_an_array_and_drops_what_is_not_a_number() -> None:
    from array import array

    cells = array("f", [3.7, float("nan"), 4.2])
    fields = [float32(24.4283390045166), math.nan, True, "1.5", 1e39, None, 7]
    assert f32_all(fields, cells) == [24.428339, None, None, None, None, None, 7.0, 3.7, None, 4.2]
    assert f32_all([0.5], np.array([0.1, 1e40])) == [0.5, 0.1, None]  # float64 items too


@pytest.mark.parametrize(
    ("value", "steps", "written"),
    [
        (1.23456789, MM, 1.235),
        (-0.0004, MM, 0.0),  # no -0.0 in the JSON
        (47.123456789, LATLON, 47.1234568),
        (82.499999, PERCENT, 82.5),
        (1e300, MM, 1e300),  # too large to scale: kept as it is
        (math.nan, MM, None),
        (True, MM, None),
    ],
)
def test_derived_values_are_rounded_to_their_resolution(
    value: object, steps: float, written: float | None
) -> None:
    got = rounded(value, steps)
    assert got == written
    if written is not None:
        assert repr(got) == repr(written)


def test_degrees_are_rounded_to_a_thousandth() -> None:
    assert degrees(1.0) == 57.296
    assert degrees(-math.pi) == -180.0
    assert degrees(1e307) is None  # overflows when converted
    assert quaternion_to_yaw_deg(NS(x=0.0, y=0.0, z=0.3826834, w=0.9238795)) == 45.0
