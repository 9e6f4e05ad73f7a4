"""The phytrace_edge node: topic subscriptions feed the builder, the sample timer emits.

Written against ``RosApi`` so it runs on real rclpy and on the mock layer unchanged;
``run_simulation`` and ``phytrace-edge run`` both use it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from phytrace_edge.build import Identity, UDMBuilder
from phytrace_edge.config import Settings
from phytrace_edge.ingest.dispatch import Dispatcher
from phytrace_edge.ingest.ros import NodeClock, RosApi, TopicSubscriber, create_sample_timer

NODE_NAME = "phytrace_edge"
GRAPH_CHECK_S = 2.0  # how often new topics and new publishers are looked for


def identity_of(settings: Settings) -> Identity:
    return Identity(settings.source_id, settings.source_type, settings.fleet_id, settings.site_id)


class BridgeNode:
    """Subscriptions -> dispatcher -> builder; every 1/SAMPLE_RATE_HZ: ``emit(event)``."""

    def __init__(
        self, api: RosApi, settings: Settings, emit: Callable[[dict[str, Any]], None]
    ) -> None:
        self.node = api.create_node(NODE_NAME)
        self.builder = UDMBuilder(
            identity_of(settings),
            stale_after_s=settings.stale_after_s,
            use_sim_time=settings.use_sim_time,
            clock=NodeClock(api),
        )
        self.dispatcher = Dispatcher(self.builder.add_reading)
        self._emit = emit
        self.subscriber = TopicSubscriber(
            api, self.node, settings.topics, self.dispatcher, settings.topic_qos
        )
        self.subscriber.refresh()
        self.graph_timer = self.node.create_timer(
            GRAPH_CHECK_S, self.subscriber.refresh, clock=api.clock("steady")
        )
        self.timer = create_sample_timer(api, self.node, settings.sample_rate_hz, self.tick)

    @property
    def qos_incompatible(self) -> dict[str, int]:
        return dict(self.subscriber.qos_incompatible)

    def tick(self) -> None:
        self._emit(self.builder.build_event())
