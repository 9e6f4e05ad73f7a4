"""A Cyclone DDS robot that sends strings which are not UTF-8, for test_dds_text.py (run
as a script): the types are the dds input's own (so the writers match its readers, type
information and all), and a broken sample is one whose serialised string has two of its
bytes replaced by 0xff 0xfe, which no UTF-8 decoder accepts; the CDR string keeps its
length and its NUL, so only the decoding of the text fails.

    dds_text_publisher.py   (ROS_DOMAIN_ID and ROS_LOCALHOST_ONLY from the environment)

It prints ``ready``, then publishes the warm-up every 50 ms: status ``s0`` on
/delivery/status, a good /odom, an OK /diagnostics. Commands on stdin, each answered
``sent`` once written:

- ``burst``: the warm-up stops; one /odom whose frame_id is broken, then statuses
  ``s1`` .. ``s9``, ``s6`` broken, with /diagnostics WARN ``d1`` .. ``d3`` among them
- ``last``: status ``s10``

It exits when stdin closes.
"""

from __future__ import annotations

import json
import os
import queue
import sys
import threading
from typing import Any

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from phytrace_edge.ingest.sources import dds_types as t
from phytrace_edge.ingest.sources.dds import dds_topic_name, domain_config
from phytrace_edge.ingest.sources.dds_env import domain_settings
from tests.integration.dds_publisher import idl_sample
from tests.ros.known import KNOWN

RELIABLE = Qos(
    Policy.Reliability.Reliable(max_blocking_time=duration(seconds=1)), Policy.History.KeepLast(50)
)
BEST_EFFORT = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(5))
BROKEN = 6  # the status that is not UTF-8
DIAGNOSTICS_AFTER = {1: "d1", 3: "d2", 7: "d3"}  # status index -> the WARN written after it


def not_utf8(sample: Any, text: str) -> Any:
    """``sample``, written with the first two bytes of ``text`` (found once in its
    serialised form) replaced by 0xff 0xfe. DataWriter.write serialises with
    ``sample.serialize(...)``: an attribute of the instance takes the method's place."""
    marker = text.encode()

    def serialize(**kwargs: Any) -> bytes:
        raw = type(sample).serialize(sample, **kwargs)
        assert raw.count(marker) == 1, (marker, raw)
        return raw.replace(marker, b"\xff\xfe" + marker[2:])

    sample.serialize = serialize
    return sample


def status(index: int) -> t.String_:
    sample = t.String_(data=json.dumps({"order_id": "o-1", "state": f"s{index}"}))
    return not_utf8(sample, f"s{index}") if index == BROKEN else sample


def diagnostics(name: str, level: int) -> t.DiagnosticArray_:
    statuses: Any = [t.DiagnosticStatus_(level=level, name=name, message="hot", hardware_id="mc")]
    return t.DiagnosticArray_(status=statuses)


def odom() -> Any:
    return idl_sample(t.Odometry_, KNOWN["/odom"][2])


def main() -> None:
    domain_id, localhost = domain_settings(os.environ)
    domain = Domain(domain_id, domain_config(localhost_only=True)) if localhost else None
    participant = DomainParticipant(domain_id)

    def writer(topic: str, kind: type, qos: Qos) -> DataWriter:
        return DataWriter(participant, Topic(participant, dds_topic_name(topic), kind), qos=qos)

    statuses = writer("/delivery/status", t.String_, RELIABLE)
    diagnostic = writer("/diagnostics", t.DiagnosticArray_, RELIABLE)
    odometry = writer("/odom", t.Odometry_, BEST_EFFORT)
    commands: queue.Queue[str | None] = queue.Queue()

    def read_commands() -> None:
        for line in sys.stdin:
            commands.put(line.strip())
        commands.put(None)

    threading.Thread(target=read_commands, daemon=True).start()
    print("ready", flush=True)
    warming = True
    while True:
        try:
            command = commands.get(timeout=0.05)
        except queue.Empty:
            if warming:  # until both sides have surely matched: the test waits for it
                statuses.write(status(0))
                odometry.write(odom())
                diagnostic.write(diagnostics("warmup", 0))
            continue
        if command is None:
            break
        if command == "burst":
            warming = False
            odometry.write(not_utf8(odom(), "odom"))  # header.frame_id
            for index in range(1, 10):
                statuses.write(status(index))
                if index in DIAGNOSTICS_AFTER:
                    diagnostic.write(diagnostics(DIAGNOSTICS_AFTER[index], 1))
        elif command == "last":
            statuses.write(status(10))
        print("sent", flush=True)
    del domain


if __name__ == "__main__":
    main()
