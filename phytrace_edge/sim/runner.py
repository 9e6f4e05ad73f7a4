"""``run_simulation``: the simulated delivery robot and the bridge, end to end.

The robot node and the bridge node share one mock ROS context. By default time is
virtual, so 100 ticks (10 s of robot time at 10 Hz) run in a fraction of a second;
``realtime=True`` runs at wall-clock pace.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Any

from phytrace_edge.config import Settings
from phytrace_edge.runtime.ros_node import BridgeNode
from phytrace_edge.sim.mock_ros import Context, SingleThreadedExecutor, init, ros_api, shutdown
from phytrace_edge.sim.robot import DeliveryRobot
from phytrace_edge.sim.world import World
from phytrace_edge.udm.schema import check_event

log = logging.getLogger(__name__)

ROBOT_TICK_HZ = 10.0
Event = dict[str, Any]


def run_simulation(
    num_ticks: int = 100,
    *,
    settings: Settings | None = None,
    sink: Callable[[Event], None] | None = None,
    seed: int = 0,
    realtime: bool = False,
) -> dict[str, Any]:
    """Run the simulated robot for ``num_ticks`` robot cycles (10 Hz) through the bridge.

    Every built event is validated against the UDM schema and handed to ``sink``
    (default: kept in memory and discarded at the end). Returns
    ``{"events_sent", "events_failed", "topics_seen", "duration_s"}``: events the sink
    accepted, events that failed validation or that the sink refused, the topics the
    bridge received messages on, and the wall-clock duration of the run.
    """
    if num_ticks < 0:
        raise ValueError("num_ticks must be >= 0")
    settings = settings or Settings()
    collected: list[Event] = []
    sink = sink or collected.append
    counts = {"sent": 0, "failed": 0}

    context = Context(virtual_time=not realtime)
    init(context=context)
    api = ros_api(context)
    started = time.monotonic()
    try:
        robot_node = api.create_node("delivery_robot")
        robot = DeliveryRobot(robot_node, World.create(seed), tick_hz=ROBOT_TICK_HZ)
        robot_node.create_timer(1.0 / ROBOT_TICK_HZ, robot.tick, clock=api.clock("steady"))

        def emit(event: Event) -> None:
            if not check_event(event, log):
                counts["failed"] += 1
                return
            try:
                sink(event)
            except Exception:
                log.exception("sink refused event %s", event["event_id"])
                counts["failed"] += 1
            else:
                counts["sent"] += 1

        bridge = BridgeNode(api, settings, emit)
        executor = SingleThreadedExecutor(context, [robot_node, bridge.node])
        while robot.ticks < num_ticks and context.ok():
            executor.spin_once(timeout_sec=1.0)
    finally:
        shutdown(context=context)
    return {
        "events_sent": counts["sent"],
        "events_failed": counts["failed"],
        "topics_seen": bridge.builder.topics_seen(),
        "duration_s": round(time.monotonic() - started, 3),
    }
