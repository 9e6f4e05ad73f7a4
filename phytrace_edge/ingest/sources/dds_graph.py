"""What the ``dds`` input knows of the graph: the writers on its domain, read from
Cyclone DDS's built-in ``DCPSPublication`` topic, with the QoS each offers. Its readers
then follow the same QoS rules as the ``ros`` input's subscriptions (``ingest.qos``),
and ``status`` shows each topic's publishers.

Imported only by the ``dds`` input (it needs cyclonedds).
"""

from __future__ import annotations

from typing import Any

from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication
from cyclonedds.core import InstanceState, Policy, ReadCondition, SampleState, ViewState

Offer = tuple[bool, bool]  # what a writer offers: (reliable, transient local)
PUBLICATIONS_MAX = 4096  # writers read in one look; a robot has a few hundred


def offer_of(qos: Any) -> Offer:
    """(reliable, transient local) of a writer's QoS. A policy the writer did not
    announce has its DDS default for writers: reliable, volatile."""
    reliability = qos[Policy.Reliability]
    durability = qos[Policy.Durability]
    return (
        reliability is None or isinstance(reliability, Policy.Reliability.Reliable),
        durability == Policy.Durability.TransientLocal,
    )


class Publications:
    """The live writers of a domain, as the participant ``participant`` discovered them."""

    def __init__(self, participant: Any) -> None:
        self._reader = BuiltinDataReader(participant, BuiltinTopicDcpsPublication)
        any_sample = ViewState.Any | SampleState.Any
        self._alive = ReadCondition(self._reader, any_sample | InstanceState.Alive)
        self._gone = ReadCondition(
            self._reader,
            any_sample | InstanceState.NotAliveDisposed | InstanceState.NotAliveNoWriters,
        )

    def offers(self) -> dict[tuple[str, str], list[Offer]]:
        """(DDS topic name, DDS type name) -> what each live writer of it offers."""
        # writers that went away are taken out, so that the cache holds the live ones
        self._reader.take(N=PUBLICATIONS_MAX, condition=self._gone)
        found: dict[tuple[str, str], list[Offer]] = {}
        for writer in self._reader.read(N=PUBLICATIONS_MAX, condition=self._alive):
            found.setdefault((writer.topic_name, writer.type_name), []).append(offer_of(writer.qos))
        return found
