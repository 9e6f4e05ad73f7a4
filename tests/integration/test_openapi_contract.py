"""The stub answers exactly as docs/phycloud-openapi.yaml says: every route is in the
document, every answer's body matches the documented schema for its status code, and
hostile bodies (hypothesis) never get a 5xx or an undocumented status."""

from __future__ import annotations

import gzip
import json
from pathlib import Path

import httpx
import orjson
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from jsonschema import Draft202012Validator
from openapi_spec_validator import validate

from phytrace_edge import run_simulation
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


@pytest.fixture(scope="module")
def events() -> list[dict]:
    out: list[dict] = []
    run_simulation(40, sink=out.append)
    return out


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
    statuses = {(path, r.request.method, r.status_code) for r, path in cases}
    assert {("/events", "POST", s) for s in (200, 400, 401, 415)} <= statuses
    for response, path in cases:
        check(response, path)
    stub.set_faults(fixed_status=503, retry_after="3")
    injected = httpx.post(f"{url}/events", content=body, headers=auth)
    check(injected, "/events")
    assert injected.status_code == 503 and injected.headers["retry-after"] == "3"
    assert "Retry-After" in SPEC["paths"]["/events"]["post"]["responses"]["503"]["headers"]


def test_every_stub_route_is_in_the_document(tmp_path: Path) -> None:
    store = StubStore(tmp_path / "stub.db")
    try:
        app = create_app(Stub(store, Faults(), api_key=None, seed=0))
        paths = {route.path for route in app.routes if route.path.startswith("/api/")}
    finally:
        store.close()
    assert paths == {f"/api/v1{path}" for path in SPEC["paths"]}


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
