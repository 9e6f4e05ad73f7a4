"""The mock's executor: runs ready callbacks of its nodes, one per ``spin_once``, in
the thread that spins (as rclpy's SingleThreadedExecutor does), in real or virtual time.
"""

from __future__ import annotations

import functools
import itertools
from collections.abc import Callable
from dataclasses import dataclass, field

from phytrace_edge.sim.mock_ros.runtime import Context, Node, default_context


@dataclass
class SingleThreadedExecutor:
    """Runs one ready callback per ``spin_once``, oldest work first."""

    context: Context = field(default_factory=default_context)
    nodes: list[Node] = field(default_factory=list)
    _turn: itertools.count = field(default_factory=itertools.count)

    def add_node(self, node: Node) -> bool:
        if node not in self.nodes:
            self.nodes.append(node)
        return True

    def spin_once(self, timeout_sec: float | None = None) -> None:
        source = self.context.time_source
        deadline = None if timeout_sec is None else source.steady_ns() + int(timeout_sec * 1e9)
        with self.context.condition:
            while self.context.ok():
                work = self._ready_work()
                if work is not None:
                    break
                wake = self._next_timer_ns()
                if deadline is not None:
                    wake = deadline if wake is None else min(wake, deadline)
                if wake is None and source.virtual:
                    return  # virtual time with nothing scheduled: nothing can ever happen
                if deadline is not None and source.steady_ns() >= deadline:
                    return
                source.wait(self.context.condition, wake)
            else:
                return
        work()

    def spin(self) -> None:
        while self.context.ok() and self.nodes:
            self.spin_once(timeout_sec=0.1)

    def _ready_work(self) -> Callable[[], None] | None:
        """The next callback to run, or None (caller holds the condition)."""
        for node in self.nodes:
            for subscription in node.subscriptions:
                if subscription.pending_events and subscription.event_callbacks.incompatible_qos:
                    event = subscription.pending_events.pop(0)
                    callback = subscription.event_callbacks.incompatible_qos
                    return functools.partial(callback, event)
            ready = [s for s in node.subscriptions if s.pending]
            if ready:
                subscription = ready[next(self._turn) % len(ready)]
                msg = subscription.pending.popleft()
                return functools.partial(subscription.callback, msg)
        for node in self.nodes:
            for timer in node.timers:
                if timer.is_ready():
                    return timer.fire
        return None

    def _next_timer_ns(self) -> int | None:
        calls = [t.next_call_ns for n in self.nodes for t in n.timers if not t.cancelled]
        return min(calls) if calls else None
