"""The stub's live page in headless Chromium: robots, rates and values appear, and the
screenshot shows a drawn page (not a blank one); incidents are listed and the chosen
one's window is plotted around its trigger, a point per sample."""

from __future__ import annotations

import html
import math
import re
import shutil
import struct
import subprocess
import time
import zlib
from collections.abc import Callable
from datetime import datetime
from pathlib import Path
from typing import Any

import httpx
import orjson
import pytest
import zstandard

from phytrace_edge import run_simulation
from phytrace_edge.builder.envelope import envelope
from phytrace_edge.config import load_settings
from phytrace_edge.incident.parts import ClosedIncident, Sample, incident_events
from phytrace_edge.incident.triggers import Trigger
from phytrace_edge.udm.event import new_event_id, parse_timestamp

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


# ---- incidents: the list and the chosen incident's window, plotted around its trigger

SERIES_SOURCES: dict[str, list[tuple[str, Callable[[dict], Any]]]] = {
    "speed": [("/odom", lambda s: _hypot(s.get("linear_velocity") or {}))],
    "yaw": [
        ("/odom", lambda s: (s.get("angular_velocity") or {}).get("yaw_dps")),
        ("/imu/data", lambda s: ((s.get("imu") or {}).get("angular_velocity_dps") or {}).get("z")),
    ],
    "battery": [("/battery_state", lambda s: (s.get("battery") or {}).get("state_of_charge_pct"))],
}


def _hypot(velocity: dict) -> float | None:
    x, y = velocity.get("x_mps"), velocity.get("y_mps")
    return math.hypot(x, y) if isinstance(x, float | int) and isinstance(y, float | int) else None


def plotted(parts: list[dict]) -> dict[str, tuple[str, list[tuple[str, float]]]]:
    """What the page is to draw of the parts received: per series, the first source
    (topic) that has the value and (t, value) of every sample of it."""
    samples: dict[str, list[dict]] = {}
    for event in sorted(parts, key=lambda e: e["incident"]["part"]):
        for topic, items in event["incident"]["samples"].items():
            samples.setdefault(topic, []).extend(items)
    out = {}
    for key, sources in SERIES_SOURCES.items():
        for topic, value in sources:
            points = [(s["t"], value(s)) for s in samples.get(topic, [])]
            points = [(t, v) for t, v in points if isinstance(v, float | int)]
            if points:
                out[key] = (topic, points)
                break
    return out


def attributes(html: str, tag: str, cls: str) -> dict[str, str]:
    """The attributes of the first ``<tag class="cls" ...>`` in ``html``."""
    found = re.search(rf'<{tag} class="{cls}"([^>]*)>', html)
    assert found, f"no <{tag} class={cls!r}>"
    return dict(re.findall(r'([\w:-]+)="([^"]*)"', found.group(1)))


def page(tmp_path: Path, url: str, *args: str) -> str:
    """The page's DOM after its scripts ran, without the scripts' own text."""
    dom = chromium(tmp_path, *args, "--dump-dom", url).stdout
    assert "<script" in dom, "no page"
    return dom[: dom.index("<script")]


def check_view(dom: str, parts: list[dict]) -> dict[str, int]:
    """The incident view shows these parts' incident: each series it has plotted with
    one point per sample at its time relative to the trigger, the trigger marked at 0,
    the series it lacks said to be absent. Strokes per plotted series."""
    incident = parts[0]["incident"]
    view = dom[dom.index('id="incident-view"') :]
    assert f'<div data-incident="{incident["id"]}">' in view, "another incident is shown"
    trigger = parse_timestamp(incident["trigger"]["at"])
    series = plotted(parts)
    assert series, "the test's incident has something to plot"
    ends = [parse_timestamp(p[i][0]) - trigger for _, p in series.values() for i in (0, -1)]
    window = incident["window"]
    t0 = min(parse_timestamp(window["start"]) - trigger, 0, *ends)
    t1 = max(parse_timestamp(window["end"]) - trigger, 0, *ends)
    strokes = {}
    for key in SERIES_SOURCES:
        figure = re.search(rf'<figure class="plot" data-series="{key}"(.*?)</figure>', view, re.S)
        if key not in series:
            assert figure is None, f"{key} is drawn, but the incident has none"
            assert f'<p class="absent" data-series="{key}">' in view
            continue
        assert figure, f"no plot of {key}"
        plot, (topic, points) = figure.group(1), series[key]
        assert f'data-topic="{topic}"' in plot, f"{key} is not drawn from {topic}"
        frame = attributes(plot, "rect", "frame")
        left, width = float(frame["x"]), float(frame["width"])
        top, bottom = float(frame["y"]), float(frame["y"]) + float(frame["height"])

        def x(t: float, left: float = left, width: float = width) -> float:
            return left + width * (t - t0) / (t1 - t0)

        marker = attributes(plot, "line", "trigger")
        assert abs(float(marker["x1"]) - x(0.0)) < 0.011 and marker["x1"] == marker["x2"], key
        drawn = re.findall(r"([ML])(-?[\d.]+),(-?[\d.]+)", attributes(plot, "path", "series")["d"])
        assert len(drawn) == len(points), f"{key}: {len(drawn)} points for {len(points)} samples"
        for (_, px, py), (t, _) in zip(drawn, points, strict=True):
            assert abs(float(px) - x(parse_timestamp(t) - trigger)) < 0.011, (key, t)
            assert top <= float(py) <= bottom
        values, ys = [v for _, v in points], [float(py) for _, _, py in drawn]
        assert ys[values.index(max(values))] == min(ys), f"{key}: the highest value on top"
        strokes[key] = sum(1 for move, _, _ in drawn if move == "M")
    return strokes


def crafted_incident(source_id: str, trigger_wall: float) -> list[dict]:
    """An incident of a robot with an IMU and no odometry or battery: 2 s of /imu/data
    at 50 Hz around a manual mark."""
    samples = [
        Sample(
            "/imu/data",
            trigger_wall - 1.0 + i * 0.02 + 0.0007,  # microseconds matter in a 2.5 s window
            orjson.dumps({"imu": {"angular_velocity_dps": {"x": 0.0, "y": 0.0, "z": i % 9}}}),
        )
        for i in range(100)
    ]
    mark = Trigger("manual", "hit the shelf <aisle 4>", 101.0, trigger_wall)
    closed = ClosedIncident(mark, 100.0, 102.5, trigger_wall - 1.0, trigger_wall + 1.5, samples)
    identity = {"source_id": source_id, "source_type": "amr"}
    return [dict(e) for e in incident_events(identity, closed, 1_000_000)]  # type: ignore[arg-type]


def greenish(pixel: tuple[int, int, int]) -> bool:  # the battery line, on white or blended
    r, g, b = pixel
    return g - r > 40 and g - b > 25


def bluish(pixel: tuple[int, int, int]) -> bool:  # the speed line
    r, g, b = pixel
    return b - r > 70 and b - g > 50


def test_page_plots_an_incident_around_its_trigger(tmp_path: Path, stub) -> None:
    events: list[dict] = []
    settings = load_settings(env={"BATCH_MAX_BYTES": "32KiB"}).settings
    run_simulation(400, settings=settings, sink=events.append)
    by_id: dict[str, list[dict]] = {}
    for e in events:
        if e["event_type"] == "incident":
            by_id.setdefault(e["incident"]["id"], []).append(e)
    assert len(by_id) >= 2, "the simulated robot's ERRORs give incidents"
    sim = sorted(by_id.values(), key=lambda parts: parts[0]["incident"]["trigger"]["at"])
    newest, older = sim[-1], sim[-2]
    assert len(older) >= 3, "incidents in parts (BATCH_MAX_BYTES)"
    lost = older[1]  # part 2 of the older one never arrives
    first_at = parse_timestamp(events[0]["captured_at"])
    imu_only = crafted_incident("amr-9", first_at - 3600)

    others = [e for e in events if e["event_type"] != "incident"]
    assert httpx.post(
        f"{stub.endpoint}/events", content=orjson.dumps({"events": others})
    ).is_success
    compress = zstandard.ZstdCompressor()
    for part in [e for e in events if e["event_type"] == "incident" and e is not lost] + imu_only:
        response = httpx.post(  # a part per request, as the bridge queues them
            f"{stub.endpoint}/events",
            content=compress.compress(orjson.dumps({"events": [part]})),
            headers={"Content-Encoding": "zstd"},
        )
        assert response.json()["accepted"] == 1

    shot = tmp_path / "incident.png"
    size = ("--window-size=1280,2000", "--force-device-scale-factor=0.5")
    dom = page(tmp_path, f"{stub.url}/", *size, f"--screenshot={shot}")
    # the list: newest first, each with its robot, trigger, message and parts n/N
    listed = re.findall(r'<li data-incident="([^"]+)"', dom)
    ids = [p[0]["incident"]["id"] for p in reversed(sim)] + [imu_only[0]["incident"]["id"]]
    assert listed == ids
    assert f'<li data-incident="{ids[0]}" class="selected">' in dom, "the newest is shown"
    for parts, received in ((newest, len(newest)), (older, len(older) - 1), (imu_only, 1)):
        incident = parts[0]["incident"]
        item = re.search(rf'<li data-incident="{incident["id"]}"[^>]*>(.*?)</li>', dom, re.S)
        assert item, incident["id"]
        text = html.unescape(item.group(1))
        assert parts[0]["source_id"] in text and incident["trigger"]["message"] in text
        kind = " ".join(
            filter(None, (incident["trigger"]["kind"], incident["trigger"].get("level")))
        )
        assert kind in text  # "rosout error", "manual"
        assert f"parts {received}/{incident['parts']}" in text
        at, window = incident["trigger"]["at"], incident["window"]
        assert f"{at[:10]} {at[11:19]}" in text  # when
        span = [parse_timestamp(window[end]) - parse_timestamp(at) for end in ("start", "end")]
        assert (
            "window {} … {}".format(*(f"{'+' if s > 0 else '−'}{abs(s):.1f} s" for s in span))
            in text
        )
    assert f"parts {len(older) - 1}/{len(older)} · missing 2" in html.unescape(dom)
    # the newest: speed, yaw rate (/odom) and battery, one stroke each
    assert check_view(dom, newest) == {"speed": 1, "yaw": 1, "battery": 1}

    # the incomplete one: its lines break where part 2 belongs
    dom = page(tmp_path, f"{stub.url}/#incident={older[0]['incident']['id']}")
    received = [e for e in older if e is not lost]
    assert check_view(dom, received) == {"speed": 2, "yaw": 2, "battery": 2}
    assert '<rect class="gap"' in dom and "part 2 missing" in dom

    # no odometry nor battery: yaw rate from /imu/data, the others said to be absent
    control = tmp_path / "imu-only.png"
    url = f"{stub.url}/#incident={imu_only[0]['incident']['id']}"
    dom = page(tmp_path, url, *size, f"--screenshot={control}")
    assert check_view(dom, imu_only) == {"yaw": 1}
    assert 'data-topic="/imu/data"' in dom and "speed: absent from this incident" in dom
    assert "battery: absent from this incident" in dom

    pixels, without = png_pixels(shot), png_pixels(control)
    assert len(set(pixels)) > 50, "the screenshot looks blank"
    # the same page but for the plots of speed and battery (the IMU-only incident has none)
    for colour, what in ((bluish, "speed"), (greenish, "battery")):
        more = sum(map(colour, pixels)) - sum(map(colour, without))
        assert more > 150, f"no {what} plot drawn ({more} more pixels of its colour)"
