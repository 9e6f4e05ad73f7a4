"""A ROS graph for the tests: a robot node, the bridge's ``ros`` input, the stub.

The same test bodies run on these graphs:

- ``jazzy`` and ``kilted``: real rclpy from the package index, ROS 2 Jazzy (the
  ``jazzy`` extra: ``ros-jazzy-rclpy[fastrtps]``, rclpy 7.1) in ``.venv-jazzy`` and
  Kilted (the ``kilted`` extra: rclpy 9.1) in ``.venv-kilted``, both on Fast DDS, which
  ``tools/test.py`` installs. The robot and the bridge are two processes on a private
  ROS domain confined to loopback.
- ``humble`` (optional): ROS 2 Humble has no wheels; a build of it (from source, or
  /opt/ros/humble) is tested only when ``PHYTRACE_ROS_HUMBLE_SETUP`` names its
  ``setup.bash``: the robot and the bridge run with the environment it sets, on
  ``PHYTRACE_ROS_HUMBLE_PYTHON`` (default: ``python3`` on the PATH it sets; it needs
  the project's dependencies, the checkout is on PYTHONPATH), on
  ``PHYTRACE_ROS_HUMBLE_RMW`` (default: rmw_cyclonedds_cpp) with ROS_LOCALHOST_ONLY
  (Humble has no discovery range). Unset, there is no ``humble`` flavour at all.
- ``mock``: the mock rclpy installed as ``rclpy`` in one process that is both the
  robot and, once started, the bridge (the mock's graph lives in one process).

Either way the bridge is ``phytrace-edge run --input ros``, unchanged, sending to a
real stub over loopback, and the test sees what an operator sees: the events at the
stub, ``status``, the exit code and the log.
"""

from __future__ import annotations

import functools
import json
import os
import random
import shutil
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

from tests.processes import ROOT, StubProcess, python_env, wait_for

# real rclpy, by ROS 2 distribution: each in a venv of its own (their wheels conflict)
ROS_PYTHONS = {
    "jazzy": ROOT / ".venv-jazzy" / "bin" / "python",
    "kilted": ROOT / ".venv-kilted" / "bin" / "python",
}
# ROS 2 Humble, from a build of it: only when PHYTRACE_ROS_HUMBLE_SETUP names one
HUMBLE_SETUP = os.environ.get("PHYTRACE_ROS_HUMBLE_SETUP", "")
# the RMW (a source build on Debian's Cyclone DDS has this one; Humble's default and
# the other flavours': rmw_fastrtps_cpp)
HUMBLE_RMW = os.environ.get("PHYTRACE_ROS_HUMBLE_RMW", "rmw_cyclonedds_cpp")


@functools.cache
def sourced(setup: str) -> dict[str, str]:
    """The variables ``source SETUP`` sets or changes in bash, the checkout first on
    the Python path (as ``python_env`` puts it for the other flavours)."""
    dump = subprocess.run(
        ["bash", "-c", 'source "$1" >&2 && env -0', "bash", setup],
        capture_output=True,
        timeout=60,
    ).stdout.decode()
    env = dict(item.split("=", 1) for item in dump.split("\0") if "=" in item)
    changed = {
        k: v
        for k, v in env.items()
        if os.environ.get(k) != v and k not in ("_", "SHLVL", "PWD", "OLDPWD")
    }
    return changed | {
        "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    }


if HUMBLE_SETUP:
    ROS_PYTHONS["humble"] = Path(
        os.environ.get("PHYTRACE_ROS_HUMBLE_PYTHON")
        or shutil.which("python3", path=sourced(HUMBLE_SETUP).get("PATH"))
        or "python3"
    )
DISTROS = tuple(ROS_PYTHONS)
ROS_PYTHON = ROS_PYTHONS["kilted"]  # where colcon and ament_cmake are (the ros-build extra)
# every graph of a test session gets a domain of its own: a participant killed by an
# earlier test lingers in its domain until its lease runs out
_DOMAINS = iter(random.Random().sample(range(1, 200), 199))


def private_domain() -> int:
    return next(_DOMAINS)


ROBOT = str(Path(__file__).with_name("robot.py"))
EVENT_WAIT_S = 60.0


def rclpy_missing(distro: str = "kilted") -> str | None:
    """Why real rclpy of ``distro`` cannot run here, or None."""
    python = ROS_PYTHONS[distro]
    if distro == "humble" and not Path(HUMBLE_SETUP).is_file():
        return f"no {HUMBLE_SETUP} (PHYTRACE_ROS_HUMBLE_SETUP): a Humble build's setup.bash"
    if not python.exists():
        return f"no {python}: python3 tools/test.py installs the ROS 2 {distro} wheels there"
    probe = subprocess.run(  # the bridge's service: its dependencies too
        [str(python), "-c", "import rclpy, sensor_msgs.msg, phytrace_edge.runtime.service"],
        capture_output=True,
        text=True,
        timeout=120,
        env=os.environ | (sourced(HUMBLE_SETUP) if distro == "humble" else {}),
    )
    if probe.returncode != 0:
        return f"rclpy does not import in {python}: {probe.stderr.strip().splitlines()[-1:]}"
    return None


def ros_env(domain: int, log_dir: Path, distro: str = "kilted") -> dict[str, str]:
    """A private ROS domain on loopback only (no discovery traffic leaves the host)."""
    if distro == "humble":  # before Iron: no discovery range; the build's environment
        return sourced(HUMBLE_SETUP) | {
            "ROS_DOMAIN_ID": str(domain),
            "ROS_LOCALHOST_ONLY": "1",
            "RMW_IMPLEMENTATION": HUMBLE_RMW,
            "ROS_LOG_DIR": str(log_dir),
        }
    return {
        "ROS_DOMAIN_ID": str(domain),
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
        "RMW_IMPLEMENTATION": "rmw_fastrtps_cpp",
        "ROS_LOG_DIR": str(log_dir),
    }


class CommandedProcess:
    """A script in a process of its own that answers one JSON line per command on its
    stdin (``robot.py``, ``dds_robot.py``) and prints ``ready`` first."""

    def __init__(
        self, command: list[str], env: dict[str, str], log: Path, uid: int | None = None
    ) -> None:
        as_user: dict[str, Any] = {} if uid is None else {"user": uid, "group": uid}
        with log.open("a") as stderr:
            self.process = subprocess.Popen(
                command,
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=stderr,
                text=True,
                env=python_env() | env,  # env may set PYTHONPATH (a sourced build)
                **as_user,
            )
        self.log = log
        assert self._answer() == "ready"

    def _answer(self) -> Any:
        line = self.process.stdout.readline()  # type: ignore[union-attr]
        if not line:
            raise AssertionError(f"the robot exited ({self.process.poll()}); see {self.log}")
        answer = json.loads(line)
        if not answer["ok"]:
            raise AssertionError(f"robot: {answer['error']}")
        return answer["result"]

    def command(self, op: str, **args: Any) -> Any:
        self.process.stdin.write(json.dumps({"op": op, **args}) + "\n")  # type: ignore[union-attr]
        self.process.stdin.flush()  # type: ignore[union-attr]
        return self._answer()

    def close(self) -> None:
        """End of stdin: the robot leaves the graph cleanly; killed if it does not."""
        stop_by_pid(self.process, lambda: self.process.stdin.close())  # type: ignore[union-attr]


class Robot(CommandedProcess):
    """``robot.py`` in a process of its own: real rclpy of a distro (``jazzy``,
    ``kilted``, ``humble``) or the mock (``mock``: that process also runs the bridge,
    when told), as this user or as ``uid``."""

    def __init__(
        self, flavour: str, env: dict[str, str], log: Path, uid: int | None = None
    ) -> None:
        self.python = sys.executable if flavour == "mock" else str(ROS_PYTHONS[flavour])
        argv = [self.python, ROBOT, *(["--mock"] if flavour == "mock" else [])]
        super().__init__(argv, env, log, uid)

    def publisher(self, topic: str, type_name: str, qos: str) -> int:
        return int(self.command("publisher", topic=topic, type=type_name, qos=qos))

    def publish(self, publisher: int, fields: dict[str, Any], matched_within_s: float = 0) -> int:
        return int(
            self.command("publish", id=publisher, fields=fields, matched_within_s=matched_within_s)
        )

    def publish_at(self, publisher: int, fields: dict[str, Any], hz: float, seconds: float) -> int:
        return int(self.command("publish_at", id=publisher, fields=fields, hz=hz, seconds=seconds))


def stop_by_pid(process: subprocess.Popen[Any], ask: Any, grace_s: float = 10) -> None:
    """``ask`` the process to end, then kill it if it has not within ``grace_s``."""
    if process.poll() is None:
        ask()
        try:
            process.wait(timeout=grace_s)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait(timeout=20)


class Rig:
    """A robot, a bridge to start, and the stub it sends to."""

    def __init__(self, flavour: str, tmp: Path, stub: StubProcess) -> None:
        self.flavour, self.tmp, self.stub = flavour, tmp, stub
        self.queue_path = tmp / "queue.db"
        self.bridge_log = tmp / "bridge.log"
        self.env = ros_env(private_domain(), tmp / "ros-logs", flavour)
        self.settings: dict[str, str] = {}
        # on the mock, the robot's process becomes the bridge: one log
        robot_log = self.bridge_log if flavour == "mock" else tmp / "robot.log"
        self.robot = Robot(flavour, self.env, robot_log)
        self.command = self.robot.command
        self.publisher = self.robot.publisher
        self.publish = self.robot.publish
        self.publish_at = self.robot.publish_at
        self.bridge: subprocess.Popen[bytes] | None = None

    def parameters(self, node: str, call: str, answer_s: float = 2.0, **args: Any) -> Any:
        return self.command("parameters", node=node, call=call, answer_s=answer_s, **args)

    def call_trigger(self, service: str, answer_s: float = 10.0) -> dict[str, Any] | None:
        """A ``std_srvs/srv/Trigger`` service called from the robot's node: its answer
        (``success``, ``message``), or None when none came within ``answer_s``."""
        answer: dict[str, Any] | None = self.command(
            "call_trigger", service=service, answer_s=answer_s
        )
        return answer

    # the bridge
    def start_bridge(
        self,
        *ros_args: str,
        command: list[str] | None = None,
        process_env: dict[str, str] | None = None,
        **settings: str,
    ) -> None:
        """``phytrace-edge run --input ros`` with the rig's settings (``settings``
        replace them; "" unsets one). On real rclpy, ``command`` and ``process_env``
        replace the module's command and environment (an installed executable)."""
        self.settings = {
            "PHYCLOUD_ENDPOINT": self.stub.endpoint,
            "PHYCLOUD_API_KEY": "phk_test_secret_key",
            "QUEUE_PATH": str(self.queue_path),
            "SOURCE_ID": f"ros-{self.flavour}",
            "SAMPLE_RATE_HZ": "5",
            "FLUSH_INTERVAL_S": "0.3",
            "RETRY_MIN_S": "0.05",
            "RETRY_MAX_S": "0.5",
            "HEALTH_EVENT_INTERVAL_S": "0",
            **settings,
        }
        self.settings = {k: v for k, v in self.settings.items() if v}  # "" = leave unset
        argv = ["run", "--input", "ros", *(["--ros-args", *ros_args] if ros_args else [])]
        if self.flavour == "mock":
            self.command("start_bridge", argv=argv, env=self.settings)
            return
        command = command or [self.robot.python, "-m", "phytrace_edge", "run"]
        env = (process_env or python_env()) | self.env | self.settings
        with self.bridge_log.open("a") as log:
            self.bridge = subprocess.Popen([*command, *argv[1:]], stdout=log, stderr=log, env=env)

    @property
    def bridge_process(self) -> subprocess.Popen[Any]:
        process = self.robot.process if self.flavour == "mock" else self.bridge
        assert process is not None, "start_bridge() first"
        return process

    def stop_bridge(self, signum: int = signal.SIGTERM, timeout: float = 60) -> tuple[int, str]:
        """Signal the bridge; its exit code and everything it logged."""
        os.kill(self.bridge_process.pid, signum)
        code = self.bridge_process.wait(timeout=timeout)
        return code, self.bridge_log.read_text()

    def status(self, *flags: str) -> tuple[int, str]:
        result = subprocess.run(
            [sys.executable, "-m", "phytrace_edge", "status", *flags],
            capture_output=True,
            text=True,
            timeout=60,
            env=python_env(QUEUE_PATH=str(self.queue_path)),
        )
        return result.returncode, result.stdout

    def status_json(self) -> dict[str, Any]:
        _, out = self.status("--json")
        return json.loads(out) if out else {}

    def publish_until(
        self, publisher: int, fields: dict[str, Any], predicate: Any, what: str
    ) -> Any:
        """Publish again and again, as a sensor does, until an event satisfies
        ``predicate``; that event."""

        def found() -> Any:
            self._bridge_alive()
            self.publish(publisher, fields)
            return next((e for e in reversed(self.events()) if predicate(e)), None)

        return wait_for(found, EVENT_WAIT_S, what, every=0.2)

    def wait_running(self) -> None:
        """Until the bridge's heartbeat says it runs (a robot that publishes nothing
        gives no events to wait for)."""
        wait_for(
            lambda: self._bridge_alive() or self.status_json().get("running"),
            EVENT_WAIT_S,
            "the bridge to run",
            every=0.2,
        )

    def events(self, event_type: str = "telemetry.periodic") -> list[dict[str, Any]]:
        return [e for e in self.stub.events() if e["event_type"] == event_type]

    def wait_event(self, predicate: Any, what: str, event_type: str = "telemetry.periodic") -> Any:
        def found() -> Any:
            self._bridge_alive()
            return next((e for e in reversed(self.events(event_type)) if predicate(e)), None)

        return wait_for(found, EVENT_WAIT_S, what, every=0.2)

    def wait_incident(self, incident_id: str | None = None) -> list[dict[str, Any]]:
        """Every part of an incident at the stub (``incident_id``'s, or the first
        one's), by part number, once all of them came."""

        def complete() -> list[dict[str, Any]] | None:
            self._bridge_alive()
            events = self.events("incident")
            ident = incident_id or next((e["incident"]["id"] for e in events), None)
            parts = sorted(
                (e for e in events if e["incident"]["id"] == ident),
                key=lambda e: e["incident"]["part"],
            )
            return parts if parts and len(parts) == parts[0]["incident"]["parts"] else None

        parts: list[dict[str, Any]] = wait_for(
            complete, EVENT_WAIT_S, f"incident {incident_id or ''} at the stub", every=0.2
        )
        return parts

    def _bridge_alive(self) -> None:
        code = self.bridge_process.poll()
        if code is not None:
            raise AssertionError(f"the bridge exited ({code}):\n{self.bridge_log.read_text()}")

    def close(self) -> None:
        """Stop the bridge as systemd would, then the robot (killed if they linger)."""
        if self.settings:  # started: on the mock, in the robot's own process
            bridge = self.bridge_process
            stop_by_pid(bridge, lambda: bridge.send_signal(signal.SIGTERM))
        self.robot.close()
