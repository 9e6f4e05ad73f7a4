"""The topic table drives the bridge: its handlers write only the keys their readings
declare, its domains are exactly what each domain is built from, every topic whose
messages all matter has an accumulator, and README's table says what the table says."""

from __future__ import annotations

import re
import typing
from pathlib import Path
from typing import Any, get_type_hints

import pytest

from phytrace_edge.builder.assemble import DOMAIN_BUILDERS, DOMAIN_TOPICS, Snapshot
from phytrace_edge.builder.builder import UDMBuilder
from phytrace_edge.builder.options import BuilderOptions, Identity
from phytrace_edge.ingest import readings
from phytrace_edge.ingest.topics import DOMAINS, TOPIC_BY_NAME, TOPICS
from phytrace_edge.sim.mock_ros.messages import message_type
from tests.ros.fields import fill
from tests.ros.known import KNOWN

ROOT = Path(__file__).resolve().parents[2]


def undeclared_keys(value: Any, declared: Any, at: str = "") -> list[str]:
    """Keys of ``value`` that the TypedDict ``declared`` (or those nested in it) lacks."""
    if not typing.is_typeddict(declared) or not isinstance(value, dict):
        return []
    hints = get_type_hints(declared)
    found = [f"{at}.{key}" for key in value if key not in hints]
    for key, inner in value.items():
        if key in hints:
            found += undeclared_keys(inner, hints[key], f"{at}.{key}")
            element = typing.get_args(hints[key])
            if isinstance(inner, list) and element:
                for item in inner:
                    found += undeclared_keys(item, element[0], f"{at}.{key}[]")
    return found


def mock_class(type_name: str) -> type:
    """``sensor_msgs/msg/Imu`` or ``sensor_msgs/Imu`` -> the mock's class."""
    package, *_, name = type_name.split("/")
    return message_type(f"{package}/msg/{name}")


def known_message(topic: str) -> Any:
    type_name, _, fields = KNOWN[topic]
    return fill(mock_class(type_name)(), fields, mock_class)


def known_readings() -> dict[str, Any]:
    return {topic: TOPIC_BY_NAME[topic].handler(known_message(topic)) for topic in KNOWN}


@pytest.mark.parametrize("topic", sorted(KNOWN))
def test_a_handler_writes_only_what_its_reading_declares(topic: str) -> None:
    spec = TOPIC_BY_NAME[topic]
    reading = spec.handler(known_message(topic))
    declared = get_type_hints(spec.handler)["return"]
    assert reading, "the known message gave an empty reading"
    assert undeclared_keys(reading, declared) == []
    assert get_type_hints(readings.Readings)[topic] is declared  # the same type per topic


def test_undeclared_keys_finds_a_renamed_key() -> None:
    assert undeclared_keys({"imu": {"orientation": {}}}, readings.ImuReading) == [
        ".imu.orientation"
    ]


def test_readings_by_topic_are_the_table_without_rosout() -> None:
    assert set(get_type_hints(readings.Readings)) == {s.name for s in TOPICS} - {"/rosout"}


def test_each_domain_is_built_from_exactly_the_topics_the_table_names() -> None:
    """Built from only its own topics' readings, a domain is what it is from all of
    them; and each of those topics is used: without it the domain changes, or it
    alone gives the domain something (the IMU's yaw rate stands in for odometry's)."""
    everything = known_readings()
    snapshot = Snapshot(latest={})
    assert list(DOMAIN_BUILDERS) == list(DOMAINS)
    for domain, build in DOMAIN_BUILDERS.items():
        topics = DOMAIN_TOPICS[domain]
        assert topics, f"no topic feeds {domain}"
        own = {topic: everything[topic] for topic in topics}
        assert build(own, snapshot) == build(everything, snapshot), domain  # type: ignore[arg-type]
        for topic in topics:
            without = {t: r for t, r in own.items() if t != topic}
            alone = {topic: own[topic]}
            used = build(without, snapshot) != build(own, snapshot) or build(alone, snapshot)  # type: ignore[arg-type]
            assert used, (domain, topic)


def test_every_topic_whose_messages_all_matter_is_accumulated() -> None:
    builder = UDMBuilder(BuilderOptions(Identity("bot", "amr")))
    every_message = {spec.name for spec in TOPICS if spec.every_message}
    assert set(builder.accumulators) == every_message - {"/rosout"}  # rosout: log records


def test_the_readme_topic_table_is_the_topic_table() -> None:
    readme = (ROOT / "README.md").read_text()
    rows = re.findall(r"^\| `(/[^`]+)` \| `([^`]+)`[^|]*\| ([^|]+) \|", readme, re.MULTILINE)
    expected = [
        (s.name, s.type_name.replace("/msg/", "/"), ", ".join(s.domains))
        for s in TOPICS
        if s.domains
    ]
    notes = re.compile(r" \([^)]*\)")  # "location (heading)": a note for the reader
    found = [(topic, kind, notes.sub("", domains).strip()) for topic, kind, domains in rows]
    assert found == expected
