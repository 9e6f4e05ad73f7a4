"""A plain Cyclone DDS robot for the DDS source's test (run as a script): publishes the
ten topics with known values, ROS 2 wire names and types, until stdin closes; and, for
TOPICS_EXTRA, the known messages of the generic conversion's test (``EXTRA``) and a
log record on /rosout.

    dds_publisher.py     (ROS_DOMAIN_ID and ROS_LOCALHOST_ONLY come from the environment)
"""

from __future__ import annotations

import os
import sys
import threading
import typing
from typing import Any

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from phytrace_edge.ingest.sources import dds_types as t
from phytrace_edge.ingest.sources.dds import dds_topic_name, domain_config
from phytrace_edge.ingest.sources.dds_env import domain_settings
from tests.ros.known import KNOWN

BEST_EFFORT = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(5))
RELIABLE = Qos(
    Policy.Reliability.Reliable(max_blocking_time=duration(seconds=1)), Policy.History.KeepLast(10)
)


QOS = {"best_effort": BEST_EFFORT, "reliable": RELIABLE, "latched": RELIABLE}


def idl_sample(cls: type, fields: dict[str, Any]) -> Any:
    """An IDL sample of ``cls`` from ``tests.ros.known``'s plain data."""
    hints = typing.get_type_hints(cls, include_extras=True)
    values: dict[str, Any] = {}
    for name, value in fields.items():
        if isinstance(value, dict):
            values[name] = idl_sample(hints[name], value)
        elif isinstance(value, list) and value and isinstance(value[0], dict):
            element = typing.get_args(hints[name])[1].subtype
            values[name] = [idl_sample(element, item) for item in value]
        else:
            values[name] = value
    return cls(**values)


def samples() -> dict[str, tuple[object, Qos]]:
    """The ten topics' known messages, in the dds input's own IDL types."""
    return {
        topic: (idl_sample(t.DDS_TYPES[type_name], fields), QOS[qos])
        for topic, (type_name, qos, fields) in KNOWN.items()
    }


def extra_samples() -> dict[str, tuple[object, Qos]]:
    """Messages of types outside the table, in the types the dds input makes itself."""
    from tests.unit.test_generic import (
        compressed_image,
        float32_array,
        temperature,
        tf_message,
        to_idl,
    )

    log = t.Log_(
        stamp=t.Time_(sec=1_763_000_000), level=40, name="acme.drive", msg="overcurrent", line=7
    )
    return {
        EXTRA["/motor/temperature"]: (to_idl(temperature()), RELIABLE),
        EXTRA["/tf"]: (to_idl(tf_message()), BEST_EFFORT),
        EXTRA["/cells"]: (to_idl(float32_array()), BEST_EFFORT),
        EXTRA["/camera"]: (to_idl(compressed_image()), BEST_EFFORT),
        "/rosout": (log, RELIABLE),
    }


# extra topic -> its name on the wire (here, the same)
EXTRA = {t: t for t in ("/motor/temperature", "/tf", "/cells", "/camera")}


def main() -> None:
    domain_id, localhost = domain_settings(os.environ)
    domain = Domain(domain_id, domain_config(localhost_only=True)) if localhost else None
    participant = DomainParticipant(domain_id)
    writers = []
    for topic_name, (sample, qos) in (samples() | extra_samples()).items():
        topic = Topic(participant, dds_topic_name(topic_name), type(sample))
        writers.append((DataWriter(participant, topic, qos=qos), sample))
    print("ready", flush=True)
    done = threading.Event()
    threading.Thread(target=lambda: (sys.stdin.read(), done.set()), daemon=True).start()
    while not done.wait(0.05):  # 20 Hz, as a robot would
        for writer, sample in writers:
            writer.write(sample)
    del domain


if __name__ == "__main__":
    main()
