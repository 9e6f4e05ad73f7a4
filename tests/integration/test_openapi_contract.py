"""The stub answers exactly as docs/phycloud-openapi.yaml says: every route is in the
document, every answer's body matches the documented schema for its status code (the
incidents' too, of incident events posted first), the documented schemas refuse wrong
answers, and hostile bodies (hypothesis) never get a 5xx or an undocumented status."""

from __future__ import annotations

import asyncio
import gzip
import json
from pathlib import Path
from typing import Any

import httpx
import orjson
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from jsonschema import Draft202012Validator
from openapi_spec_validator import validate

from phytrace_edge import run_simulation
from phytrace_edge.incident.parts import (
    PART_HEADROOM_BYTES,
    ClosedIncident,
    Sample,
    incident_events,
)
from phytrace_edge.incident.triggers import Trigger
from phytrace_edge.stub import store as stub_store
from phytrace_edge.stub.app import Stub, create_app
from phytrace_edge.stub.faults import Faults
from phytrace_edge.stub.store import StubStore

SPEC = yaml.safe_load((Path(__file__).parents[2] / "docs" / "phycloud-openapi.yaml").read_text())


def response_schema(path: str, method: str, status: int) -> dict:
    responses = SPEC["paths"][path][method]["responses"]
    assert str(status) in responses, f"{method.upper()} {path} answered undocumented {status}"
    content = responses[str(status)].get("content", {}).get("application/json", {})
    schema = content.get("schema", {})
    return {**schema, "components": SPEC["components"]} if schema else {}


def check(response: httpx.Response, path: str) -> None:
    method = response.request.method.lower()
    schema = response_schema(path, method, response.status_code)
    if schema:  # "$ref": "#/components/..." resolves against the components added above
        Draft202012Validator(schema).validate(response.json())


def violations(body: Any, path: str, status: int) -> list[str]:
    """What makes ``body`` not the documented answer of GET ``path`` with ``status``."""
    schema = response_schema(path, "get", status)
    return [error.message for error in Draft202012Validator(schema).iter_errors(body)]


@pytest.fixture(scope="module")
def events() -> list[dict]:
    out: list[dict] = []
    run_simulation(40, sink=out.append)
    return out


def incident_parts(source_id: str, trigger: Trigger, **closed: Any) -> list[dict]:
    """The parts (3 or more) of an incident of ``source_id`` around ``trigger``: 3 s of
    /odom at 20 Hz and /battery_state at 2 Hz, as the bridge sends them."""
    start = trigger.wall_s - 1.0
    samples = []
    for i in range(60):
        wall = start + i * 0.05
        odom = {"linear_velocity": {"x_mps": 0.01 * i, "y_mps": 0.2, "z_mps": 0.0}}
        samples.append(Sample("/odom", wall, orjson.dumps(odom)))
        if i % 10 == 0:
            battery = {"battery": {"state_of_charge_pct": 80 - i / 100}}
            samples.append(Sample("/battery_state", wall + 0.001, orjson.dumps(battery)))
    window = ClosedIncident(
        trigger, trigger.at_s - 1.0, trigger.at_s + 2.0, start, start + 3.0, samples, **closed
    )
    size = sum(len(s.json) + 50 for s in samples)
    identity = {"source_id": source_id, "source_type": "amr"}
    parts = incident_events(identity, window, PART_HEADROOM_BYTES + size // 3 + 200)  # type: ignore[arg-type]
    assert len(parts) >= 3, "the test's split"
    return [dict(e) for e in parts]


def stored_incidents(post: Any) -> tuple[list[dict], list[dict]]:
    """Posts two incidents with ``post(events)``: a complete one triggered by hand, and a
    later one with everything an incident may have (a trigger's topic and level,
    ``triggers``, ``dropped``, ``cut_short``) but its part 2, so that it has a gap.
    (complete, incomplete) as sent."""
    wall = 1_795_000_000.0
    complete = incident_parts("amr-7", Trigger("manual", "hit the shelf", 100.0, wall))
    diagnostics = Trigger(
        "diagnostics", "lidar: no data", 700.0, wall + 600, "/diagnostics", "error"
    )
    incomplete = incident_parts(
        "amr-8", diagnostics, triggers=2, dropped={"/odom": 12}, cut_short=True
    )
    post(complete + incomplete[:1] + incomplete[2:])
    return complete, incomplete


def test_the_document_is_valid_openapi() -> None:
    validate(SPEC)


def test_documented_answers_have_documented_bodies(stub_factory, events) -> None:
    stub = stub_factory("--api-key", "k")
    auth = {"Authorization": "Bearer k"}
    url = stub.endpoint
    body = orjson.dumps({"events": events})
    cases = [
        (httpx.post(f"{url}/events", content=body, headers=auth), "/events"),
        (
            httpx.post(
                f"{url}/events",
                content=gzip.compress(body),
                headers={**auth, "Content-Encoding": "gzip"},
            ),
            "/events",
        ),
        (httpx.post(f"{url}/events", content=body), "/events"),  # 401
        (httpx.post(f"{url}/events", content=b"{", headers=auth), "/events"),  # 400
        (
            httpx.post(f"{url}/events", content=orjson.dumps({"events": [{"x": 1}]}), headers=auth),
            "/events",
        ),  # 400 with index
        (
            httpx.post(f"{url}/events", content=body, headers={**auth, "Content-Encoding": "br"}),
            "/events",
        ),  # 415
        (httpx.get(f"{url}/stats"), "/stats"),
        (httpx.get(f"{url}/events", params={"limit": 5}), "/events"),
        (httpx.get(f"{url}/events", params={"limit": 0}), "/events"),  # 400
        (httpx.get(f"{url}/robots"), "/robots"),
        (httpx.get(f"{url}/faults"), "/faults"),
        (httpx.put(f"{url}/faults", json={"latency_s": 0}), "/faults"),
        (httpx.put(f"{url}/faults", json={"latency_s": -1}), "/faults"),  # 400
    ]

    def post(events: list[dict]) -> None:
        answer = httpx.post(f"{url}/events", content=orjson.dumps({"events": events}), headers=auth)
        assert answer.json()["accepted"] == len(events), answer.text

    complete, incomplete = stored_incidents(post)
    listed = httpx.get(f"{url}/incidents")
    assert [i["id"] for i in listed.json()["incidents"]] == [
        incomplete[0]["incident"]["id"],
        complete[0]["incident"]["id"],
    ], "both incidents, newest first"
    assert listed.json()["incidents"][0]["gaps"], "the incomplete one has a gap to check"
    one = f"{url}/incidents/{incomplete[0]['incident']['id']}"
    assert httpx.get(one).json()["samples"]["/odom"], "samples to check"
    too_many = {"topic": [f"/t{i}" for i in range(257)]}
    unknown = f"{url}/incidents/01a21991-7bb0-7a37-97e1-cb3e9e6a3b9f"
    cases += [
        (listed, "/incidents"),
        (httpx.get(f"{url}/incidents", params={"source_id": "amr-7", "limit": 1}), "/incidents"),
        (httpx.get(f"{url}/incidents", params={"limit": 0}), "/incidents"),  # 400
        (httpx.get(one), "/incidents/{incident_id}"),
        (httpx.get(one, params={"topic": "/battery_state"}), "/incidents/{incident_id}"),
        (httpx.get(one, params=too_many), "/incidents/{incident_id}"),  # 400
        (httpx.get(unknown), "/incidents/{incident_id}"),  # 404
    ]
    statuses = {(path, r.request.method, r.status_code) for r, path in cases}
    assert {("/events", "POST", s) for s in (200, 400, 401, 415)} <= statuses
    assert {("/incidents", "GET", s) for s in (200, 400)} <= statuses
    assert {("/incidents/{incident_id}", "GET", s) for s in (200, 400, 404)} <= statuses
    for response, path in cases:
        check(response, path)
    stub.set_faults(fixed_status=503, retry_after="3")
    injected = httpx.post(f"{url}/events", content=body, headers=auth)
    check(injected, "/events")
    assert injected.status_code == 503 and injected.headers["retry-after"] == "3"
    assert "Retry-After" in SPEC["paths"]["/events"]["post"]["responses"]["503"]["headers"]


def asgi_get(app: Any, url: str, **params: Any) -> httpx.Response:
    """GET ``url`` of the stub's app in this process (httpx's ASGI transport)."""

    async def ask() -> httpx.Response:
        transport = httpx.ASGITransport(app=app)
        async with httpx.AsyncClient(transport=transport, base_url="http://stub") as client:
            return await client.get(url, params=params)

    return asyncio.run(ask())


def test_incident_answers_are_documented_and_wrong_ones_refused(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    store = StubStore(tmp_path / "stub.db")
    try:
        stub = Stub(store, Faults(), api_key=None, seed=0)
        app = create_app(stub)
        _, incomplete = stored_incidents(lambda events: store.record(events))
        one = f"/api/v1/incidents/{incomplete[0]['incident']['id']}"
        listed = asgi_get(app, "/api/v1/incidents").json()
        incident = asgi_get(app, one).json()
        assert violations(listed, "/incidents", 200) == []
        assert violations(incident, "/incidents/{incident_id}", 200) == []

        # 413: the samples asked for over the bound
        monkeypatch.setattr(stub_store, "MAX_INCIDENT_BYTES", 100)
        too_large = asgi_get(app, one)
        assert too_large.status_code == 413
        check(too_large, "/incidents/{incident_id}")
    finally:
        store.close()

    # the documented schemas are closed and typed: a wrong answer does not pass
    entry = listed["incidents"][0]
    wrong_lists = [
        {**listed, "next_after": 0},
        {"incidents": [{**entry, "samples": {}}]},  # the list carries no samples
        {"incidents": [{k: v for k, v in entry.items() if k != "gaps"}]},
        {"incidents": [{**entry, "parts": "3"}]},
        {"incidents": [{**entry, "missing_parts": [0]}]},
        {"incidents": [{**entry, "trigger": {**entry["trigger"], "kind": "bump"}}]},
        {"incidents": [{**entry, "window": {"start": entry["window"]["start"]}}]},
        {"incidents": [{**entry, "gaps": [{**entry["gaps"][0], "from": None}]}]},
        {"incidents": [{**entry, "sample_counts": {"/odom": -1}}]},
        {"incidents": [{**entry, "captured_at": "yesterday"}]},
        {"incidents": [{**entry, "cut_short": False}]},
    ]
    for wrong in wrong_lists:
        assert violations(wrong, "/incidents", 200), wrong
    odom = incident["samples"]["/odom"]
    wrong_incidents = [
        {**incident, "extra": 1},
        {k: v for k, v in incident.items() if k != "samples"},
        {k: v for k, v in incident.items() if k != "trigger"},
        {**incident, "samples": {"/odom": [{k: v for k, v in odom[0].items() if k != "t"}]}},
        {**incident, "samples": {"/odom": [{**odom[0], "t": entry["captured_at"]}]}},  # ms
        {**incident, "complete": "no"},
    ]
    for wrong in wrong_incidents:
        assert violations(wrong, "/incidents/{incident_id}", 200), wrong
    assert violations({"message": "no"}, "/incidents/{incident_id}", 404)


def test_every_stub_route_is_in_the_document(tmp_path: Path) -> None:
    store = StubStore(tmp_path / "stub.db")
    try:
        app = create_app(Stub(store, Faults(), api_key=None, seed=0))
        routes = {str(getattr(route, "path", "")) for route in app.routes}
    finally:
        store.close()
    paths = {path for path in routes if path.startswith("/api/")}
    assert paths == {f"/api/v1{path}" for path in SPEC["paths"]}
    assert routes - paths == {"/", "/healthz"}, "the stub's JSON answers are all under /api/v1"


json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(max_size=20),
    lambda children: (
        st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=8), children, max_size=4)
    ),
    max_leaves=20,
)


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(document=json_values, encoding=st.sampled_from(["identity", "gzip", "zstd", "deflate"]))
def test_hostile_bodies_get_documented_answers(stub, document, encoding: str) -> None:
    # the stdlib encoder also writes integers beyond 64 bits, which orjson cannot read
    raw = json.dumps({"events": document} if isinstance(document, list) else document).encode()
    body = gzip.compress(raw) if encoding == "gzip" else raw  # zstd/deflate: invalid on purpose
    response = httpx.post(
        f"{stub.endpoint}/events", content=body, headers={"Content-Encoding": encoding}, timeout=10
    )
    assert response.status_code < 500
    check(response, "/events")
