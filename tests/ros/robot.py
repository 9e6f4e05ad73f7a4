"""A robot for the ROS tests: one node that publishes, logs and asks other nodes for
their parameters as the test tells it, one JSON command a line on stdin, one answer a
line on stdout. The same code runs on real rclpy and on the mock:

    robot.py          real rclpy; the bridge runs in a process of its own
    robot.py --mock   the mock installed as ``rclpy``; told ``start_bridge``, this
                      process runs ``phytrace-edge run`` in its main thread on the same
                      mock graph (the mock's graph does not cross processes)

Commands (``op`` and its arguments) -> ``{"ok": true, "result": ...}`` or
``{"ok": false, "error": "..."}``:

    publisher  topic, type, qos ("best_effort", "reliable", "latched")  -> its id
    publish    id, fields (tests.ros.known's form), matched_within_s (optional: wait
               until a subscription matched first)                       -> subscriptions
    publish_at id, fields, hz, seconds: again and again, as a sensor does -> messages
    message_info id, fields: one message published and taken back as the bridge takes
               one (``take_message``)  -> its message info's kinds of value, stamps
    log        level ("info", "warning", "error"), text
    nodes                                                                 -> full names
    parameters node, call ("list", "get", "describe", "set"), names or values,
               answer_s -> the answer, or null when none came within answer_s
    call_trigger service (a std_srvs/srv/Trigger service's name), answer_s
               -> {"success", "message"}, or null when no answer came within answer_s
    start_bridge argv, env (--mock only)
"""

from __future__ import annotations

import json
import os
import queue
import sys
import threading
import time
import traceback
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the checkout, for tests.ros

from tests.ros.fields import fill, message_class

DISCOVERY_S = 20.0  # to find another node's parameter services


class Robot:
    def __init__(self, rclpy: Any) -> None:
        from rclpy.executors import SingleThreadedExecutor

        self.node = rclpy.create_node("robot")
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        self.publishers: list[Any] = []

    def publisher(self, topic: str, type: str, qos: str) -> int:
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

        profile = QoSProfile(
            depth=1 if qos == "latched" else 10,
            reliability=ReliabilityPolicy.BEST_EFFORT
            if qos == "best_effort"
            else ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL
            if qos == "latched"
            else DurabilityPolicy.VOLATILE,
        )
        self.publishers.append(self.node.create_publisher(message_class(type), topic, profile))
        return len(self.publishers) - 1

    def publish(self, id: int, fields: dict[str, Any], matched_within_s: float = 0.0) -> int:
        publisher = self.publishers[id]
        deadline = time.monotonic() + matched_within_s
        while publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.01)  # polling the middleware's match count, with a deadline
        publisher.publish(fill(publisher.msg_type(), fields))
        return int(publisher.get_subscription_count())

    def publish_at(self, id: int, fields: dict[str, Any], hz: float, seconds: float) -> int:
        publisher = self.publishers[id]
        msg = fill(publisher.msg_type(), fields)
        start, sent = time.monotonic(), 0
        while time.monotonic() < start + seconds:
            publisher.publish(msg)
            sent += 1
            time.sleep(max(0.0, start + sent / hz - time.monotonic()))  # the sensor's pace
        return sent

    def message_info(self, id: int, fields: dict[str, Any]) -> dict[str, Any]:
        publisher = self.publishers[id]
        subscription = self.node.create_subscription(
            publisher.msg_type, publisher.topic_name, lambda msg: None, publisher.qos_profile
        )
        deadline = time.monotonic() + DISCOVERY_S
        try:
            while publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
                time.sleep(0.01)  # polling the middleware's match count, with a deadline
            before = time.time_ns()
            publisher.publish(fill(publisher.msg_type(), fields))
            taken = None
            while taken is None and time.monotonic() < deadline:
                with subscription.handle:
                    taken = subscription.handle.take_message(
                        subscription.msg_type, subscription.raw
                    )
                time.sleep(0 if taken else 0.01)
            after = time.time_ns()
        finally:
            self.node.destroy_subscription(subscription)
        if taken is None:
            raise RuntimeError(f"nothing to take on {publisher.topic_name}")
        info = taken[1]
        written, received = info["source_timestamp"], info["received_timestamp"]
        return {
            "kinds": {key: type(value).__name__ for key, value in info.items()},
            # no reception stamp (0): the writer's, as ros.received_ns takes it then
            "written_then_received": before <= written <= (received or written) <= after,
            "reception_stamped": received != 0,
        }

    def log(self, level: str, text: str) -> None:
        # one call site per severity: rclpy refuses another severity from the same line
        logger = self.node.get_logger()
        if level == "info":
            logger.info(text)
        elif level == "warning":
            logger.warning(text)
        else:
            logger.error(text)

    def nodes(self) -> list[str]:
        return sorted(
            f"{namespace.rstrip('/')}/{name}"
            for name, namespace in self.node.get_node_names_and_namespaces()
        )

    def parameters(self, node: str, call: str, answer_s: float, **args: Any) -> Any:
        from rclpy.parameter import Parameter, parameter_value_to_python

        try:
            from rclpy.parameter_client import AsyncParameterClient  # Iron and later
        except ImportError:  # Humble
            client: Any = ParameterServices(self.node, node)
        else:
            client = AsyncParameterClient(self.node, node)
        if not client.wait_for_services(timeout_sec=DISCOVERY_S):
            raise RuntimeError(f"{node} offers no parameter services")
        if call == "list":
            future = client.list_parameters()
        elif call == "get":
            future = client.get_parameters(args["names"])
        elif call == "describe":
            future = client.describe_parameters(args["names"])
        else:
            values = args["values"]
            future = client.set_parameters([Parameter(k, value=v) for k, v in values.items()])
        self.executor.spin_until_future_complete(future, timeout_sec=answer_s)
        if not future.done():
            return None
        response = future.result()
        if call == "list":
            return sorted(response.result.names)
        if call == "get":
            return {
                name: parameter_value_to_python(value)
                for name, value in zip(args["names"], response.values, strict=False)
            }  # no values at all: a name was not declared
        if call == "describe":
            return {
                d.name: {"read_only": d.read_only, "description": d.description}
                for d in response.descriptors
            }
        return [{"successful": r.successful, "reason": r.reason} for r in response.results]

    def call_trigger(self, service: str, answer_s: float) -> dict[str, Any] | None:
        """What ``ros2 service call SERVICE std_srvs/srv/Trigger`` does, from this node."""
        from std_srvs.srv import Trigger

        client = self.node.create_client(Trigger, service)
        try:
            if not client.wait_for_service(timeout_sec=DISCOVERY_S):
                raise RuntimeError(f"no service {service} within {DISCOVERY_S:g} s")
            future = client.call_async(Trigger.Request())
            self.executor.spin_until_future_complete(future, timeout_sec=answer_s)
            if not future.done():
                return None
            response = future.result()
            return {"success": response.success, "message": response.message}
        finally:
            self.node.destroy_client(client)


class ParameterServices:
    """What ``rclpy.parameter_client.AsyncParameterClient`` (Iron and later) does for
    the robot, on Humble: a client of each of a node's parameter services."""

    def __init__(self, node: Any, remote: str) -> None:
        from rcl_interfaces import srv

        self.clients = {
            name: node.create_client(service, f"{remote}/{name}")
            for name, service in (
                ("list_parameters", srv.ListParameters),
                ("get_parameters", srv.GetParameters),
                ("describe_parameters", srv.DescribeParameters),
                ("set_parameters", srv.SetParameters),
            )
        }

    def wait_for_services(self, timeout_sec: float) -> bool:
        deadline = time.monotonic() + timeout_sec
        return all(
            client.wait_for_service(timeout_sec=max(0.0, deadline - time.monotonic()))
            for client in self.clients.values()
        )

    def _call(self, service: str, **fields: Any) -> Any:
        client = self.clients[service]
        return client.call_async(client.srv_type.Request(**fields))

    def list_parameters(self) -> Any:
        return self._call("list_parameters")

    def get_parameters(self, names: list[str]) -> Any:
        return self._call("get_parameters", names=names)

    def describe_parameters(self, names: list[str]) -> Any:
        return self._call("describe_parameters", names=names)

    def set_parameters(self, parameters: list[Any]) -> Any:
        return self._call("set_parameters", parameters=[p.to_parameter_msg() for p in parameters])


def serve(robot: Robot, out: Any, bridge: queue.Queue[list[str] | None], mock: bool) -> None:
    """Answer commands until stdin closes; a ``start_bridge`` goes to the main thread."""
    for line in sys.stdin:
        command = json.loads(line)
        op = command.pop("op")
        try:
            if op == "start_bridge":
                if not mock:
                    raise RuntimeError("the bridge runs in a process of its own on real rclpy")
                os.environ.update(command["env"])
                bridge.put(command["argv"])
                result: Any = None
            else:
                result = getattr(robot, op)(**command)
            answer = {"ok": True, "result": result}
        except Exception as exc:
            answer = {"ok": False, "error": f"{type(exc).__name__}: {exc}"}
            traceback.print_exc()
        out.write(json.dumps(answer) + "\n")
        out.flush()
    bridge.put(None)


def main() -> int:
    mock = "--mock" in sys.argv
    # answers go to the real stdout; anything else that prints (the bridge) to stderr
    out = os.fdopen(os.dup(1), "w")
    os.dup2(2, 1)
    if mock:
        from phytrace_edge.sim.mock_ros import as_rclpy

        as_rclpy.install()
    import rclpy

    rclpy.init()
    robot = Robot(rclpy)
    bridge: queue.Queue[list[str] | None] = queue.Queue()
    threading.Thread(target=serve, args=(robot, out, bridge, mock), daemon=True).start()
    out.write(json.dumps({"ok": True, "result": "ready"}) + "\n")
    out.flush()
    argv = bridge.get()
    if argv is None:  # stdin closed
        return 0
    from phytrace_edge.cli import main as bridge_main

    return bridge_main(argv)  # in the main thread: it owns SIGTERM and SIGINT


if __name__ == "__main__":
    sys.exit(main())
