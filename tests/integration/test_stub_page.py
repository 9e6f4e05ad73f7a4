"""The stub's live page in headless Chromium: robots, rates and values appear, and the
screenshot shows a drawn page (not a blank one)."""

from __future__ import annotations

import shutil
import struct
import subprocess
import time
import zlib
from datetime import datetime
from pathlib import Path

import httpx
import orjson
import pytest

from phytrace_edge import run_simulation
from phytrace_edge.builder.envelope import envelope
from phytrace_edge.config import load_settings
from phytrace_edge.udm.event import new_event_id

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
pytestmark = pytest.mark.skipif(
    CHROMIUM is None, reason="headless Chromium is not installed (apt-get install chromium)"
)


def chromium(tmp_path: Path, *args: str) -> subprocess.CompletedProcess[str]:
    flags = [
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-dev-shm-usage",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--disable-quic",
        f"--user-data-dir={tmp_path / 'profile'}",
        "--virtual-time-budget=4000",
        "--window-size=1280,900",
    ]
    return subprocess.run([CHROMIUM, *flags, *args], capture_output=True, text=True, timeout=90)


def png_pixels(path: Path) -> list[tuple[int, int, int]]:
    """RGB(A) pixels of a non-interlaced 8-bit PNG (what Chromium writes)."""
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    pos, chunks, width = 8, b"", 0
    channels = 4
    while pos < len(data):
        length, kind = struct.unpack(">I4s", data[pos : pos + 8])
        body = data[pos + 8 : pos + 8 + length]
        if kind == b"IHDR":
            width, _, depth, color = struct.unpack(">IIBB", body[:10])
            assert depth == 8
            channels = {2: 3, 6: 4}[color]
        elif kind == b"IDAT":
            chunks += body
        pos += 12 + length
    raw, stride = zlib.decompress(chunks), width * channels
    rows, previous = [], bytearray(stride)
    for offset in range(0, len(raw), stride + 1):
        kind, line = raw[offset], bytearray(raw[offset + 1 : offset + 1 + stride])
        for i in range(stride):
            left = line[i - channels] if i >= channels else 0
            up, corner = previous[i], previous[i - channels] if i >= channels else 0
            if kind == 1:
                line[i] = (line[i] + left) & 0xFF
            elif kind == 2:
                line[i] = (line[i] + up) & 0xFF
            elif kind == 3:
                line[i] = (line[i] + (left + up) // 2) & 0xFF
            elif kind == 4:
                p = left + up - corner
                pa, pb, pc = abs(p - left), abs(p - up), abs(p - corner)
                predictor = left if pa <= pb and pa <= pc else (up if pb <= pc else corner)
                line[i] = (line[i] + predictor) & 0xFF
        rows.append(bytes(line))
        previous = line
    return [tuple(row[i : i + 3]) for row in rows for i in range(0, stride, channels)]


def test_live_page_shows_each_robot(tmp_path: Path, stub) -> None:
    events: list[dict] = []
    settings = load_settings(
        env={"TOPICS_EXTRA": "/motor/temperature mode=on_change", "ROSOUT_MIN_LEVEL": "info"}
    ).settings
    run_simulation(300, settings=settings, sink=events.append)
    health = {  # a bridge.health event, as the service emits them
        **envelope(events[-1]["identity"], "bridge.health", 1_795_338_843.0),
        "trigger": "change",
        "healthy": False,
        "problems": ["queue is 91% of QUEUE_MAX_BYTES"],
        "version": "0.1.0",
        "uptime_s": 4200.0,
        "queue": {"depth": 73},
    }
    events.append(health)
    for robot in ("amr-7", "amr-8"):
        batch = [
            {
                **e,
                "event_id": new_event_id(),
                "source_id": robot,
                "identity": {**e["identity"], "source_id": robot},
            }
            for e in events
        ]
        response = httpx.post(f"{stub.endpoint}/events", content=orjson.dumps({"events": batch}))
        assert response.status_code == 200

    dom = chromium(tmp_path, "--dump-dom", f"{stub.url}/").stdout
    assert 'data-source="amr-7"' in dom and 'data-source="amr-8"' in dom
    assert f"{2 * len(events)} events stored" in dom
    periodic = [e for e in events if e["event_type"] == "telemetry.periodic"]
    soc = periodic[-1]["power"]["battery"]["state_of_charge_pct"]
    assert f"{soc:.1f} %" in dom  # the latest battery value of the robot
    robots = httpx.get(f"{stub.endpoint}/robots").json()["robots"]
    newest = max(e["captured_at"] for e in periodic)
    lag = time.time() - datetime.fromisoformat(newest.replace("Z", "+00:00")).timestamp()
    assert all(abs(robot["lag_s"] - lag) < 30 for robot in robots), "lag from the newest event"
    assert "s behind now" in dom
    # the route, the timeline, the bridge's health, the extra topics
    robot = robots[0]
    assert len(robot["track"]) > 100 and robot["track"][-1]["frame"] == "local"
    kinds = {item["kind"] for item in robot["timeline"]}
    assert {"task", "log"} <= kinds, robot["timeline"]
    assert "task state" in dom and "-&gt;" in dom  # an INFO log line of the mission
    assert "unhealthy: queue is 91% of QUEUE_MAX_BYTES" in dom and "queue 73" in dom
    temperature = next(e for e in reversed(events) if e["event_type"] == "telemetry.topic")
    assert 'data-topic="/motor/temperature"' in dom
    assert f'"temperature":{temperature["data"]["temperature"]}' in dom

    shot = tmp_path / "page.png"
    chromium(tmp_path, f"--screenshot={shot}", f"{stub.url}/")
    pixels = png_pixels(shot)
    colours = set(pixels)
    green = sum(1 for r, g, b in pixels if g > 100 and r < 60 and b < 90)  # the battery line
    violet = sum(1 for r, g, b in pixels if 100 < r < 140 and g < 80 and b > 200)  # the route
    assert len(colours) > 50, "the screenshot looks blank"
    assert green > 200, "no battery plot drawn"
    assert violet > 200, "no route drawn"
