"""``rclpy.callback_groups`` for the mock: a group tells an executor whether it may run
one of its entities (a subscription, a timer, a service). As in rclpy, an entity the
group refuses is not even waited on: its messages stay where they are until someone
takes them."""

from __future__ import annotations

from typing import Any


class CallbackGroup:
    """The base class; a subclass decides ``can_execute``. This one runs everything,
    one at a time in the executor's thread (the mock's executor is single-threaded)."""

    def can_execute(self, entity: Any) -> bool:
        return True

    def beginning_execution(self, entity: Any) -> bool:
        return self.can_execute(entity)

    def ending_execution(self, entity: Any) -> None:
        return None


class ReentrantCallbackGroup(CallbackGroup):
    """rclpy's group that lets callbacks run in parallel; the same as the base here."""


class MutuallyExclusiveCallbackGroup(CallbackGroup):
    """rclpy's default group; with one executor thread, the same as the base here."""
