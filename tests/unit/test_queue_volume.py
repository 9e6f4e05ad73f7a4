"""Space is judged by the volume's real free space (``queue/space/volume.py``): a missing
reserve on a roomy disk is no full disk, a folder that is gone is "unknown" and never a
crash or a drop, a write that fails for another reason never evicts, the caps follow
the volume when it holds less than QUEUE_MAX_BYTES, and ``status`` judges the queue's
fill on the bytes it holds against that effective cap."""

from __future__ import annotations

import base64
import logging
import os
import random
import shutil
from pathlib import Path

import pytest

from phytrace_edge.cli.status import render_status
from phytrace_edge.errors import QueueError
from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.peek import QueueStats, file_bytes
from phytrace_edge.queue.space import caps, reserve
from phytrace_edge.queue.space.volume import (
    LIMIT_SETTING,
    LIMIT_VOLUME,
    Volume,
    effective_cap,
    look_at,
    reserve_size,
)
from phytrace_edge.runtime.health import Thresholds, report
from phytrace_edge.units import GIB, MIB
from tests.queue_events import put_events
from tests.unit.queue_fixtures import Clock, event

LIMITS = Thresholds(
    health_stale_s=15, no_progress_s=300, queue_warn_fraction=0.8, queue_max_bytes=GIB
)


@pytest.fixture
def clock() -> Clock:
    return Clock()


def noisy(n: int) -> dict:
    """An event of ~1 KB that does not compress away."""
    return {**event(n), "noise": base64.b64encode(random.Random(n).randbytes(700)).decode()}


# ------------------------------------------------------------------ the rule


def test_the_effective_cap_is_the_smaller_of_the_setting_and_the_volume() -> None:
    roomy = Volume(free=70 * GIB, size=250 * GIB)
    cap = effective_cap(GIB, 0, roomy)
    assert (cap.limited_by, cap.files, cap.bytes) == (LIMIT_SETTING, GIB, GIB - 8 * MIB)

    # a 20 MiB volume holding nothing else: its size less the reserve (1/16) and the
    # margin (256 KiB at least); of that, twice the WAL's share (1/8) is the WAL's
    small = Volume(free=20 * MIB - reserve_size(GIB, 20 * MIB), size=20 * MIB)
    cap = effective_cap(GIB, reserve_size(GIB, 20 * MIB), small)
    assert cap.limited_by == LIMIT_VOLUME
    assert cap.files == 20 * MIB - 20 * MIB // 16 - 320 * 1024
    assert cap.bytes == cap.files - 2 * (cap.files // 8)
    assert 13 * MIB < cap.bytes < 14 * MIB

    # the queue's own files are room it may reuse: a queue that filled the volume is
    # capped where it is, not below
    filled = effective_cap(GIB, 19 * MIB, Volume(free=1 * MIB, size=20 * MIB))
    assert filled.files == cap.files

    # a folder that cannot be looked at sets no limit
    assert effective_cap(GIB, 0, None).limited_by == LIMIT_SETTING


def test_a_folder_that_is_gone_is_unknown_not_an_error(tmp_path: Path) -> None:
    assert look_at(tmp_path / "gone") is None
    assert look_at(tmp_path) is not None


def test_the_put_path_looks_at_the_volume_at_most_once_a_second(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    looks: list[str] = []

    def counted(folder: str | os.PathLike[str]) -> Volume:
        looks.append(str(folder))
        return Volume(free=GIB, size=2 * GIB)

    monkeypatch.setattr(caps, "look_at", counted)
    now = [100.0]
    volume = caps.VolumeSpace(tmp_path / "queue.db", GIB, clock=lambda: now[0])
    for _ in range(1000):
        volume.cap()
        volume.look()
        now[0] += 0.0009
    assert len(looks) == 1
    now[0] += 0.2
    volume.cap()
    assert len(looks) == 2


# ------------------------------------------------------------------ the reserve


def test_a_removed_reserve_on_a_roomy_disk_is_made_again_at_once_and_drops_nothing(
    open_store, caplog: pytest.LogCaptureFixture
) -> None:
    store = open_store(compression="none")
    put_events(store, [event(i, pad=500) for i in range(50)])
    reserve = store._db.reserve
    size = reserve.path.stat().st_size
    reserve.path.unlink()  # `rm queue.db-reserve` by someone cleaning up
    store._caps.volume.forget()  # a second has passed since the last look
    with caplog.at_level(logging.INFO):
        result = put_events(store, [event(i, pad=500) for i in range(50, 100)])
        put_events(store, [event(i, pad=500) for i in range(100, 150)])
    assert (result.accepted, result.dropped) == (50, 0)
    assert reserve.path.stat().st_size == size, "made again by the put, not by maintenance"
    stats = store.stats()
    assert stats.drops == {} and stats.depth == 150
    lines = [r for r in caplog.records if "reserve" in r.getMessage()]
    assert len(lines) == 1 and "was missing" in lines[0].getMessage()


def test_a_reserve_released_for_a_full_disk_is_logged_as_back_when_room_returns(
    open_store, caplog: pytest.LogCaptureFixture
) -> None:
    store = open_store()
    reserve = store._db.reserve
    assert reserve.release()
    with caplog.at_level(logging.INFO):
        store.maintain()
    assert reserve.held()
    assert "the disk has room again; the reserve is back" in caplog.text


# ------------------------------------------------------------------ the folder is gone


@pytest.mark.parametrize("how", ["moved", "removed"])
def test_a_queue_whose_folder_is_gone_keeps_every_event_and_never_raises(
    open_store, clock: Clock, how: str
) -> None:
    store = open_store(compression="none")
    put_events(store, [event(i, pad=500) for i in range(100)])
    folder = store.path.parent
    if how == "moved":
        folder.rename(folder.with_name("elsewhere"))
    else:
        shutil.rmtree(folder)
    store._caps.volume.forget()
    for start in range(100, 400, 50):
        clock.now += 11.0  # old enough to seal: sealing must not look at a missing folder
        result = put_events(store, [event(i, pad=500) for i in range(start, start + 50)])
        assert (result.accepted, result.dropped) == (50, 0)
    assert not store._full_disk.has_room_to_seal()
    assert not store._full_disk.restore_reserve()
    stats = store.stats()
    assert stats.volume is None
    assert stats.effective_cap(GIB).limited_by == LIMIT_SETTING
    assert stats.drops == {} and stats.depth == 400, "nothing evicted, nothing refused"


def test_a_write_that_fails_for_another_reason_evicts_nothing(open_store) -> None:
    store = open_store(limits=QueueLimits(max_bytes=64 * MIB, on_full="drop_oldest"))
    put_events(store, [event(i) for i in range(40)])
    store._db.execute("PRAGMA query_only = 1")  # SQLite now refuses writes: SQLITE_READONLY
    with pytest.raises(QueueError, match="read-only"):
        put_events(store, [event(i) for i in range(40, 50)])  # the writer keeps them, retries
    store._db.execute("PRAGMA query_only = 0")
    stats = store.stats()
    assert stats.depth == 40 and stats.drops == {}, "a read-only queue is not a full disk"


# ------------------------------------------------------------------ caps follow the volume


class SmallVolume:
    """A volume of ``size`` bytes that holds only the queue: what its files do not
    take is free (what statvfs says of a tmpfs)."""

    def __init__(self, path: Path, size: int) -> None:
        self.path, self.size = path, size

    def __call__(self, folder: str | os.PathLike[str]) -> Volume:
        return Volume(max(0, self.size - file_bytes(self.path)), self.size)


@pytest.mark.parametrize("policy", ["thin", "drop_oldest"])
def test_caps_follow_a_volume_smaller_than_the_setting(
    open_store, clock: Clock, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, policy: str
) -> None:
    size = 4 * MIB
    volume = SmallVolume(tmp_path / "state" / "queue.db", size)
    monkeypatch.setattr(caps, "look_at", volume)
    monkeypatch.setattr(reserve, "look_at", volume)  # the reserve is sized by it too
    store = open_store(limits=QueueLimits(max_bytes=GIB, on_full=policy), frame_events=20)
    n = 0
    for _ in range(400):  # 400 s at 20 Hz of ~1 KB events: 8 MB, twice the volume
        put_events(store, [noisy(n + i) for i in range(20)])
        n += 20
        clock.now += 1.0
        store._caps.volume.forget()  # a second passed: look again
    cap = store._caps.cap()
    assert cap.limited_by == LIMIT_VOLUME and cap.files < size
    stats = store.stats()
    assert stats.queued_total == n and stats.depth + sum(stats.drops.values()) == n
    assert "cap_bytes" not in stats.drops, "QUEUE_MAX_BYTES was never the limit"
    if policy == "thin":
        assert stats.drops.get("thinned", 0) > 0
        assert "disk_full" not in stats.drops, "thinning made room: nothing dropped"
        first = store._db.read("SELECT min(id) FROM events")[0][0]
        assert first == 1, "the outage's start is kept (thinned), not cut off"
    else:
        assert stats.drops.get("disk_full", 0) > 0, "the volume's cap drops as disk_full"
    assert file_bytes(store.path) < size, "the files stay within the volume"
    pages, free = store._db.read(
        "SELECT page_count, freelist_count FROM pragma_page_count(), pragma_freelist_count()"
    )[0]
    assert (pages - free) * store._db.page_size <= cap.bytes


# ------------------------------------------------------------------ status


def stats_of(held: int, files: int, volume: Volume | None) -> QueueStats:
    counters = {"depth": 1234, "stored_bytes": held}
    return QueueStats("/q.db", counters, None, None, files, None, 0, volume=volume)


def test_fill_is_what_the_queue_holds_against_the_effective_cap() -> None:
    small = Volume(free=4 * MIB, size=20 * MIB)
    doc = report(stats_of(3 * MIB, 16 * MIB, small), LIMITS, 0.0)
    queue = doc["queue"]
    cap = effective_cap(GIB, 16 * MIB, small)
    assert queue["cap_limited_by"] == "volume" and queue["effective_cap_bytes"] == cap.bytes
    assert queue["held_bytes"] == 3 * MIB and queue["bytes"] == 16 * MIB
    assert queue["cap_bytes"] == GIB
    assert queue["fill"] == round(3 * MIB / cap.bytes, 4)
    assert doc["problems"] == []
    line = next(x for x in render_status(doc).splitlines() if x.startswith("  queue"))
    assert "1,234 event(s), 3 MiB held of 13.8 MiB (volume limit, 22%; files 16 MiB)" in line


def test_a_drained_queue_is_healthy_however_large_its_file_still_is() -> None:
    roomy = Volume(free=70 * GIB, size=250 * GIB)
    small_cap = LIMITS._replace(queue_max_bytes=16 * MIB)
    drained = report(stats_of(0, 14 * MIB, roomy), small_cap, 0.0)
    assert drained["queue"]["fill"] == 0.0 and drained["problems"] == []
    full = report(stats_of(11 * MIB, 14 * MIB, roomy), small_cap, 0.0)
    assert full["queue"]["cap_limited_by"] == "QUEUE_MAX_BYTES"
    assert full["problems"] == ["queue is 92% of its cap (QUEUE_MAX_BYTES): 11 MiB held of 12 MiB"]


def test_a_full_volume_is_named_as_the_limit() -> None:
    # others filled the volume: the queue may keep its own 17 MiB, less the reserve
    # and the margin, and of that the WAL's share
    doc = report(stats_of(10 * MIB, 17 * MIB, Volume(free=0, size=20 * MIB)), LIMITS, 0.0)
    assert doc["problems"] == [
        "queue is 86% of its cap (what the volume can hold): 10 MiB held of 11.6 MiB"
    ]
