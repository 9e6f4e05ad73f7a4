"""The mock's executor: runs ready callbacks of its nodes, one per ``spin_once``, in
the thread that spins (as rclpy's SingleThreadedExecutor does), in real or virtual time.
Like rclpy's, it leaves alone every entity whose callback group says it cannot run,
answers its nodes' service requests and completes their clients' futures.
"""

from __future__ import annotations

import functools
import itertools
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from phytrace_edge.sim.mock_ros.runtime import Context, Node, default_context
from phytrace_edge.sim.mock_ros.services import Future


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

    def remove_node(self, node: Node) -> None:
        if node in self.nodes:
            self.nodes.remove(node)

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

    def spin_until_future_complete(self, future: Future, timeout_sec: float | None = None) -> None:
        """Spin until ``future`` is done or ``timeout_sec`` has passed."""
        source = self.context.time_source
        deadline = None if timeout_sec is None else source.steady_ns() + int(timeout_sec * 1e9)
        while not future.done() and self.context.ok():
            left = None if deadline is None else deadline - source.steady_ns()
            if left is not None and left <= 0:
                return
            self.spin_once(timeout_sec=None if left is None else min(left / 1e9, 0.1))

    @staticmethod
    def _runs(entity: Any) -> bool:
        return bool(entity.callback_group.can_execute(entity))

    def _ready_work(self) -> Callable[[], None] | None:
        """The next callback to run, or None (caller holds the condition)."""
        for node in self.nodes:
            subscriptions = [s for s in node.subscriptions if self._runs(s)]
            for subscription in subscriptions:
                if subscription.pending_events and subscription.event_callbacks.incompatible_qos:
                    event = subscription.pending_events.pop(0)
                    callback = subscription.event_callbacks.incompatible_qos
                    return functools.partial(callback, event)
            ready = [s for s in subscriptions if s.pending]
            if ready:
                subscription = ready[next(self._turn) % len(ready)]
                msg, _ = subscription.pending.popleft()  # the callback takes the message only
                return functools.partial(subscription.callback, msg)
            for service in node.services:
                if service.pending and self._runs(service):
                    request, future, client = service.pending.popleft()
                    return functools.partial(service.answer, request, future, client)
            for client in node.clients:
                if client.responses and self._runs(client):
                    response, future = client.responses.popleft()
                    return functools.partial(future.set_result, response)
        # timers due at the same moment fire in the order they were made, whatever
        # node they belong to (rclpy's order is unspecified; a fixed one keeps a
        # simulation repeatable)
        due = [t for n in self.nodes for t in n.timers if t.is_ready() and self._runs(t)]
        if due:
            return min(due, key=lambda t: (t.next_call_ns, t.sequence)).fire
        return None

    def _next_timer_ns(self) -> int | None:
        calls = [
            t.next_call_ns
            for n in self.nodes
            for t in n.timers
            if not t.cancelled and self._runs(t)
        ]
        return min(calls) if calls else None
