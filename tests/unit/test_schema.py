"""The shipped UDM schema: the reference example validates; violations name path and value."""

from __future__ import annotations

import copy
import json
import logging
from pathlib import Path

import pytest

from phytrace_edge.builder.assemble import DOMAINS
from phytrace_edge.udm.event import format_timestamp, new_event_id
from phytrace_edge.udm.schema import check_event, find_violation, load_schema

EVENT_TYPES = ("telemetry.periodic", "telemetry.topic", "log.record", "bridge.health", "incident")
REFERENCE_EVENT = json.loads(
    (Path(__file__).parent.parent / "data/reference_event.json").read_text()
)


def test_reference_guide_example_event_validates() -> None:
    assert find_violation(REFERENCE_EVENT) is None


def test_schema_covers_every_domain_of_the_reference_event() -> None:
    properties = load_schema()["definitions"]["telemetry.periodic"]["properties"]
    for domain in DOMAINS:
        assert domain in REFERENCE_EVENT
        assert domain in properties


@pytest.mark.parametrize(
    ("mutate", "path"),
    [
        (
            lambda e: e["power"]["battery"].update(state_of_charge_pct=150.0),
            "/power/battery/state_of_charge_pct",
        ),
        (lambda e: e["location"].update(latitude=None), "/location/latitude"),
        (lambda e: e.update(source_type="boat"), "/source_type"),
        (lambda e: e["perception"]["gps"].update(fix_type="great"), "/perception/gps/fix_type"),
        (lambda e: e.update(captured_at="2025-01-15 14:23:01"), "/captured_at"),
        (lambda e: e["motion"].update(invented=1), "/motion"),
    ],
)
def test_violation_names_path_and_value(mutate, path: str) -> None:
    event = copy.deepcopy(REFERENCE_EVENT)
    mutate(event)
    violation = find_violation(event)
    assert violation is not None
    assert violation.path == path


def test_check_event_logs_warning_with_path_and_value(caplog: pytest.LogCaptureFixture) -> None:
    event = copy.deepcopy(REFERENCE_EVENT)
    event["power"]["battery"]["state_of_charge_pct"] = 150.0
    with caplog.at_level(logging.WARNING):
        assert check_event(event) is False
    assert "/power/battery/state_of_charge_pct" in caplog.text
    assert "150.0" in caplog.text
    assert caplog.records[0].levelno == logging.WARNING


def test_event_ids_are_uuid7_and_time_ordered() -> None:
    first, second = new_event_id(1_000), new_event_id(2_000)
    assert first[14] == "7" and first[19] in "89ab"
    assert first < second
    assert len({new_event_id(5) for _ in range(1000)}) == 1000


@pytest.mark.parametrize(
    ("unix_s", "text"),
    [
        (0.0, "1970-01-01T00:00:00.000Z"),
        (1736951, "1970-01-21T02:29:11.000Z"),
        (1736950981.042, "2025-01-15T14:23:01.042Z"),
        (1736950981.9996, "2025-01-15T14:23:02.000Z"),
    ],
)
def test_timestamps_are_utc_with_milliseconds(unix_s: float, text: str) -> None:
    assert format_timestamp(unix_s) == text


def _leaf_paths(schema: dict, node: dict, prefix: str) -> list[str]:
    if "$ref" in node:
        node = schema["definitions"][node["$ref"].split("/")[-1]]
    if node.get("type") == "array" and "items" in node:
        return _leaf_paths(schema, node["items"], prefix + "[]")
    if "properties" in node:
        return [
            path
            for name, child in node["properties"].items()
            if name != "sources"
            for path in _leaf_paths(schema, child, f"{prefix}.{name}" if prefix else name)
        ]
    return [prefix]


def _doc_section(doc: str, event_type: str) -> str:
    """The part of docs/udm.md under the heading that names ``event_type``."""
    start = doc.index(f"## `{event_type}`")
    end = doc.find("\n## ", start + 1)
    return doc[start : end if end > 0 else len(doc)]


@pytest.mark.parametrize("event_type", EVENT_TYPES)
def test_docs_describe_every_field_of_the_schema(event_type: str) -> None:
    """Each field of each event type is in the doc; the new types' in their section."""
    doc = (Path(__file__).parents[2] / "docs" / "udm.md").read_text()
    schema = load_schema()
    body = schema["definitions"][event_type]
    envelope = set(schema["required"]) | {"wall_clock"}  # every type's, in "Envelope"
    section = doc if event_type == "telemetry.periodic" else _doc_section(doc, event_type)
    missing = [
        path
        for path in _leaf_paths(schema, body, "")
        if f"`{path}`" not in (doc if path.split(".")[0] in envelope else section)
    ]
    assert missing == []


def test_the_stub_and_the_bridge_agree_on_validity() -> None:
    """Two validators read the one schema file; random damage must get one verdict."""
    from hypothesis import given, settings
    from hypothesis import strategies as st

    from phytrace_edge.stub.validate import find_violation as stub_violation

    def leaves(node, path=()):
        if isinstance(node, dict):
            for key, value in node.items():
                yield from leaves(value, (*path, key))
        elif isinstance(node, list):
            for index, value in enumerate(node):
                yield from leaves(value, (*path, index))
        else:
            yield path

    paths = list(leaves(REFERENCE_EVENT))
    values = st.one_of(
        st.none(),
        st.booleans(),
        st.integers(-1000, 1000),
        st.floats(-1e6, 1e6),
        st.text(max_size=300),
        st.lists(st.integers(), max_size=2),
        st.dictionaries(st.text(max_size=4), st.integers(), max_size=2),
    )

    @settings(max_examples=300, deadline=None)
    @given(path=st.sampled_from(paths), value=values)
    def agree(path, value) -> None:
        event = copy.deepcopy(REFERENCE_EVENT)
        node = event
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = value
        ours, theirs = find_violation(event), stub_violation(event)
        assert (ours is None) == (theirs is None), (path, value, ours, theirs)
        if ours is not None:
            assert ours.path == theirs.path

    agree()


def test_the_generated_validator_is_fresh_and_is_the_one_used(monkeypatch) -> None:
    """tools/generate_validator.py made it from today's schema file, so the bridge
    imports it instead of compiling at start; a stale one is not used."""
    import phytrace_edge.udm.schema as schema
    from phytrace_edge.udm import validator_generated

    assert schema.schema_sha256() == validator_generated.SCHEMA_SHA256, (
        "run tools/generate_validator.py"
    )
    schema._compiled.cache_clear()
    try:
        assert schema._compiled().__module__ == validator_generated.__name__
        monkeypatch.setattr(validator_generated, "SCHEMA_SHA256", "0" * 64)
        schema._compiled.cache_clear()
        compiled = schema._compiled()
        assert compiled.__module__ != validator_generated.__name__
        assert schema.find_violation({"event_type": "telemetry.periodic"}) is not None
    finally:
        schema._compiled.cache_clear()
