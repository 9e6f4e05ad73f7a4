"""The stub's incidents (GET /api/v1/incidents, GET /api/v1/incidents/{id}):
``incident`` events (UDM 1.3.0) posted as the bridge posts them, put together from
their parts. In process (the app on httpx's ASGI transport); the page drawing them is
in test_stub_page.py, their answers against docs/phycloud-openapi.yaml in
test_openapi_contract.py."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import httpx
import orjson
import pytest

from phytrace_edge.incident.parts import ClosedIncident, Sample, incident_events
from phytrace_edge.incident.triggers import Trigger
from phytrace_edge.stub import store as stub_store
from phytrace_edge.stub.app import Stub, create_app
from phytrace_edge.stub.faults import Faults
from phytrace_edge.stub.store import StubStore
from phytrace_edge.udm.event import format_timestamp_us

START = 1_795_000_000.0  # the window's first moment, unix seconds
TOPICS = ("/battery_state", "/imu/data", "/odom")


def samples_of(start: float, seconds: float = 6.0) -> list[Sample]:
    """/odom and /imu/data at 20 Hz and /battery_state at 2 Hz, oldest first."""
    out = []
    for i in range(int(seconds * 20)):
        wall = start + i * 0.05
        moving = {"x_mps": 0.01 * i, "y_mps": 0.2, "z_mps": 0.0}
        turning = {"roll_dps": 0.0, "pitch_dps": 0.0, "yaw_dps": float(i % 7)}
        odom = {"linear_velocity": moving, "angular_velocity": turning, "local": {"x_m": i}}
        imu = {"imu": {"angular_velocity_dps": {"x": 0.0, "y": 0.0, "z": float(i % 5)}}}
        out.append(Sample("/odom", wall, orjson.dumps(odom)))
        out.append(Sample("/imu/data", wall + 0.001, orjson.dumps(imu)))
        if i % 10 == 0:
            battery = {"battery": {"state_of_charge_pct": 80 - i / 100, "voltage_v": 24.1}}
            out.append(Sample("/battery_state", wall + 0.002, orjson.dumps(battery)))
    return out


def incident(
    source_id: str = "amr-7", start: float = START, parts: int = 3, **closed: Any
) -> tuple[list[dict[str, Any]], list[Sample]]:
    """An incident's events, split in ``parts`` parts, and its samples."""
    samples = samples_of(start)
    trigger = Trigger("diagnostics", "lidar: no data", 1003.0, start + 3.0, "/diagnostics", "error")
    window = ClosedIncident(trigger, 1000.0, 1006.0, start, start + 6.0, samples, **closed)
    size = sum(len(s.json) + 50 for s in samples)
    identity = {"source_id": source_id, "source_type": "amr"}
    events = incident_events(identity, window, 4096 + size // parts + 200)  # type: ignore[arg-type]
    assert len(events) == parts, "the test's split"
    return [dict(e) for e in events], samples


def whole(samples: list[Sample]) -> dict[str, list[dict[str, Any]]]:
    """The window's samples by topic, as an incident carries them."""
    out: dict[str, list[dict[str, Any]]] = {}
    for s in samples:
        out.setdefault(s.topic, []).append(
            {"t": format_timestamp_us(s.wall_s), **orjson.loads(s.json)}
        )
    return out


def joined(events: list[dict[str, Any]]) -> dict[str, list[dict[str, Any]]]:
    """The parts' samples joined per topic in part order."""
    out: dict[str, list[dict[str, Any]]] = {}
    for e in sorted(events, key=lambda e: e["incident"]["part"]):
        for topic, items in e["incident"]["samples"].items():
            out.setdefault(topic, []).extend(items)
    return out


class Client:
    """The stub's app in this process, asked over httpx's ASGI transport."""

    def __init__(self, db: Path) -> None:
        self.store = StubStore(db)
        self.app = create_app(Stub(self.store, Faults(), api_key=None, seed=0))

    def request(self, method: str, url: str, **kwargs: Any) -> httpx.Response:
        async def ask() -> httpx.Response:
            transport = httpx.ASGITransport(app=self.app)
            async with httpx.AsyncClient(transport=transport, base_url="http://stub") as client:
                return await client.request(method, url, **kwargs)

        return asyncio.run(ask())

    def post(self, events: list[dict[str, Any]]) -> dict[str, Any]:
        """POST /api/v1/events as the bridge sends a batch."""
        response = self.request("POST", "/api/v1/events", content=orjson.dumps({"events": events}))
        assert response.status_code == 200, response.text
        return dict(response.json())

    def get(self, url: str, **params: Any) -> httpx.Response:
        return self.request("GET", url, params=params)


@pytest.fixture
def client(tmp_path: Path) -> Any:
    c = Client(tmp_path / "stub.db")
    yield c
    c.store.close()


def test_parts_join_into_the_window_and_missing_parts_are_named(client: Client) -> None:
    events, samples = incident()
    ident = events[0]["incident"]["id"]
    assert {e["incident"]["id"] for e in events} == {ident}
    client.post([events[2]])  # the last part first, the middle one not yet
    client.post([events[0]])

    listed = client.get("/api/v1/incidents").json()["incidents"]
    assert len(listed) == 1
    entry = listed[0]
    assert entry["id"] == ident and entry["source_id"] == "amr-7"
    assert entry["trigger"] == events[0]["incident"]["trigger"]
    assert entry["trigger"]["message"] == "lidar: no data"
    assert entry["window"] == events[0]["incident"]["window"]
    assert (entry["parts"], entry["parts_received"], entry["missing_parts"]) == (3, 2, [2])
    assert entry["complete"] is False
    got = joined([events[0], events[2]])
    assert entry["sample_counts"] == {topic: len(got[topic]) for topic in TOPICS}
    # where part 2 belongs: from the last sample of part 1 to the first of part 3
    last_of_1 = max(s["t"] for items in events[0]["incident"]["samples"].values() for s in items)
    first_of_3 = min(s["t"] for items in events[2]["incident"]["samples"].values() for s in items)
    assert entry["gaps"] == [{"parts": [2], "from": last_of_1, "to": first_of_3}]

    one = client.get(f"/api/v1/incidents/{ident}").json()
    assert one["samples"] == got, "parts 1 and 3 joined in time order"
    assert {k: v for k, v in one.items() if k != "samples"} == entry

    # the missing part arrives, and part 1 again (a replay: taken once)
    answer = client.post([events[1], events[0]])
    assert (answer["accepted"], answer["duplicates"]) == (1, 1)
    entry = client.get("/api/v1/incidents").json()["incidents"][0]
    assert (entry["parts_received"], entry["missing_parts"], entry["complete"]) == (3, [], True)
    assert entry["gaps"] == []
    window = whole(samples)
    assert entry["sample_counts"] == {topic: len(window[topic]) for topic in TOPICS}
    one = client.get(f"/api/v1/incidents/{ident}").json()
    assert one["samples"] == window == joined(events), "the whole window, per topic"

    some = client.request(
        "GET", f"/api/v1/incidents/{ident}?topic=/odom&topic=/battery_state"
    ).json()
    assert some["samples"] == {t: window[t] for t in ("/battery_state", "/odom")}


def test_optional_fields_and_a_single_part(client: Client) -> None:
    events, samples = incident(parts=1, triggers=2, dropped={"/imu/data": 12}, cut_short=True)
    client.post(events)
    entry = client.get("/api/v1/incidents").json()["incidents"][0]
    assert (entry["parts"], entry["parts_received"], entry["complete"]) == (1, 1, True)
    assert (entry["triggers"], entry["dropped"], entry["cut_short"]) == (2, {"/imu/data": 12}, True)
    assert client.get(f"/api/v1/incidents/{entry['id']}").json()["samples"] == whole(samples)


def test_newest_first_limit_and_by_robot(client: Client) -> None:
    older, _ = incident("amr-7", START)
    newer, _ = incident("amr-8", START + 600)
    newest, _ = incident("amr-7", START + 1200)
    client.post(newer + newest + older)  # arrival order is not the order of the list
    ids = [e[0]["incident"]["id"] for e in (newest, newer, older)]
    assert [i["id"] for i in client.get("/api/v1/incidents").json()["incidents"]] == ids
    assert [i["id"] for i in client.get("/api/v1/incidents", limit=1).json()["incidents"]] == ids[
        :1
    ]
    by_robot = client.get("/api/v1/incidents", source_id="amr-7").json()["incidents"]
    assert [i["id"] for i in by_robot] == [ids[0], ids[2]]
    assert client.get("/api/v1/incidents", source_id="amr-9").json() == {"incidents": []}


def test_unknown_incidents_and_bad_requests(client: Client) -> None:
    events, _ = incident()
    client.post(events)
    unknown = client.get("/api/v1/incidents/01a21991-7bb0-7a37-97e1-cb3e9e6a3b9f")
    assert unknown.status_code == 404 and "no incident" in unknown.json()["error"]
    assert client.get("/api/v1/incidents/nonsense").status_code == 404
    for limit in ("0", "1001", "x"):
        bad = client.get("/api/v1/incidents", limit=limit)
        assert bad.status_code == 400 and "limit" in bad.json()["error"]
    too_many = "&".join(f"topic=/t{i}" for i in range(257))
    ident = events[0]["incident"]["id"]
    assert client.request("GET", f"/api/v1/incidents/{ident}?{too_many}").status_code == 400
    assert client.get("/api/v1/incidents", limit="1000").status_code == 200
    # under /api/v1/ only: the paths at the root are gone
    assert client.get("/incidents").status_code == 404
    assert client.get(f"/incidents/{ident}").status_code == 404


def test_an_incident_over_the_bound_is_refused(
    client: Client, monkeypatch: pytest.MonkeyPatch
) -> None:
    events, samples = incident()
    client.post(events)
    ident = events[0]["incident"]["id"]
    battery = len(orjson.dumps(whole(samples)["/battery_state"]))
    monkeypatch.setattr(stub_store, "MAX_INCIDENT_BYTES", battery + 100)
    too_large = client.get(f"/api/v1/incidents/{ident}")
    assert too_large.status_code == 413 and "fewer topics" in too_large.json()["error"]
    small = client.get(f"/api/v1/incidents/{ident}", topic="/battery_state")
    assert small.status_code == 200 and list(small.json()["samples"]) == ["/battery_state"]


def test_incidents_are_kept_and_noted_for_an_older_record(tmp_path: Path) -> None:
    stub_store_path = tmp_path / "stub.db"
    events, samples = incident()
    first = Client(stub_store_path)
    first.post(events[:2])
    before = first.get("/api/v1/incidents").json()
    entry = before["incidents"][0]
    assert (entry["parts"], entry["missing_parts"]) == (3, [3]), "the last part is missing"
    last_of_2 = max(s["t"] for items in events[1]["incident"]["samples"].values() for s in items)
    assert entry["gaps"] == [{"parts": [3], "from": last_of_2, "to": entry["window"]["end"]}]
    first.store.close()

    again = Client(stub_store_path)  # a restarted stub keeps its record
    assert again.get("/api/v1/incidents").json() == before
    # a record kept before incidents were noted beside the events: noted at open
    again.store.db.execute("DROP TABLE incident_parts")
    again.store.close()
    older = Client(stub_store_path)
    try:
        assert older.get("/api/v1/incidents").json() == before
        older.post(events[2:])
        ident = events[0]["incident"]["id"]
        assert older.get(f"/api/v1/incidents/{ident}").json()["samples"] == whole(samples)
    finally:
        older.store.close()
