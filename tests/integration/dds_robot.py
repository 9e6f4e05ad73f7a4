"""A Cyclone DDS robot that writes what the test tells it (run as a script), with ROS 2
wire names and types: one JSON command a line on stdin, one answer a line on stdout,
as ``tests/ros/robot.py`` does for rclpy. Its writers stay until stdin closes.

    writer  topic, type, qos ("best_effort", "reliable", "latched"), alone (optional:
            in a participant of its own, as a new process such as
            ``ros2 topic pub --once`` has)                            -> its id
    write   id, fields (tests.ros.known's form), matched_within_s (optional: wait
            until the writer has matched a reader first)              -> readers matched
    write_at id, fields, hz, seconds: again and again, as a sensor does  -> messages

``ROS_DOMAIN_ID`` and ``ROS_LOCALHOST_ONLY`` come from the environment.
"""

from __future__ import annotations

import json
import os
import sys
import time
import traceback
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the checkout

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from phytrace_edge.ingest.sources.dds import dds_topic_name, domain_config
from phytrace_edge.ingest.sources.dds_dynamic import idl_type
from phytrace_edge.ingest.sources.dds_env import domain_settings
from phytrace_edge.ingest.sources.dds_types import DDS_TYPES
from tests.integration.dds_publisher import idl_sample

RELIABLE = Policy.Reliability.Reliable(max_blocking_time=duration(seconds=1))
QOS = {
    "best_effort": Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(5)),
    "reliable": Qos(RELIABLE, Policy.History.KeepLast(10)),
    # what ROS 2 calls latched: the last message kept for readers that come later
    "latched": Qos(RELIABLE, Policy.Durability.TransientLocal, Policy.History.KeepLast(1)),
}


class Robot:
    def __init__(self, domain_id: int) -> None:
        self.domain_id = domain_id
        self.participant = DomainParticipant(domain_id)
        self.topics: dict[str, Any] = {}
        self.writers: list[tuple[Any, type]] = []  # and the type each writes
        self.alone: list[Any] = []  # the participants of writers on their own

    def writer(self, topic: str, type: str, qos: str, alone: bool = False) -> int:
        # the table's types as the input declares them, any other as it makes them
        cls = DDS_TYPES[type] if type in DDS_TYPES else idl_type(type)
        if alone:
            self.alone.append(DomainParticipant(self.domain_id))
            participant = self.alone[-1]
            topic_entity = Topic(participant, dds_topic_name(topic), cls)
        else:
            participant = self.participant
            if topic not in self.topics:  # one Topic entity per name in a participant
                self.topics[topic] = Topic(participant, dds_topic_name(topic), cls)
            topic_entity = self.topics[topic]
        writer = DataWriter(participant, topic_entity, qos=QOS[qos])
        self.writers.append((writer, cls))
        return len(self.writers) - 1

    def write(self, id: int, fields: dict[str, Any], matched_within_s: float = 0.0) -> int:
        writer, cls = self.writers[id]
        deadline = time.monotonic() + matched_within_s
        while not writer.get_matched_subscriptions() and time.monotonic() < deadline:
            time.sleep(0.001)  # polling the middleware's match, with a deadline
        writer.write(idl_sample(cls, fields))
        return len(writer.get_matched_subscriptions())

    def write_at(self, id: int, fields: dict[str, Any], hz: float, seconds: float) -> int:
        writer, cls = self.writers[id]
        sample = idl_sample(cls, fields)
        start, sent = time.monotonic(), 0
        while time.monotonic() < start + seconds:
            writer.write(sample)
            sent += 1
            time.sleep(max(0.0, start + sent / hz - time.monotonic()))  # the sensor's pace
        return sent


def main() -> int:
    domain_id, localhost = domain_settings(os.environ)
    domain = Domain(domain_id, domain_config(localhost_only=True)) if localhost else None
    robot = Robot(domain_id)
    print(json.dumps({"ok": True, "result": "ready"}), flush=True)
    for line in sys.stdin:
        command = json.loads(line)
        op = command.pop("op")
        try:
            answer = {"ok": True, "result": getattr(robot, op)(**command)}
        except Exception as exc:
            traceback.print_exc()
            answer = {"ok": False, "error": f"{type(exc).__name__}: {exc}"}
        print(json.dumps(answer), flush=True)
    del domain
    return 0


if __name__ == "__main__":
    sys.exit(main())
