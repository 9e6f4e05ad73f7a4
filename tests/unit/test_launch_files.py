"""The launch files, run against a recording stand-in for ROS 2's `launch` package (ROS
is not installable by pip): their arguments are those of the product's original
description (docs/ros2.md, "Launch files"), and the command they build gives the bridge
those values as ROS parameters, and only those that were given (rcl refuses an empty
`-p name:=`; checked by hand under real `ros2 launch`, see docs/ros2.md)."""

from __future__ import annotations

import runpy
import sys
import types
from pathlib import Path

import pytest

from phytrace_edge.config import ros_parameters, settings_from_environment

LAUNCH = Path(__file__).parents[2] / "phytrace_edge" / "launch"
REFERENCE = {
    "phycloud_endpoint",
    "phycloud_api_key",
    "source_id",
    "source_type",
    "fleet_id",
    "site_id",
    "sample_rate_hz",
    "batch_size",
}


class Recorded:
    def __init__(self, *args, **kwargs) -> None:
        self.args, self.kwargs = args, kwargs


class LaunchConfiguration(Recorded):
    def perform(self, context: dict[str, str]) -> str:
        return context[self.args[0]]


@pytest.fixture
def fake_launch(monkeypatch: pytest.MonkeyPatch) -> None:
    modules = {
        "launch": types.SimpleNamespace(LaunchDescription=Recorded),
        "launch.actions": types.SimpleNamespace(
            DeclareLaunchArgument=Recorded, ExecuteProcess=Recorded, OpaqueFunction=Recorded
        ),
        "launch.substitutions": types.SimpleNamespace(LaunchConfiguration=LaunchConfiguration),
    }
    for name, module in modules.items():
        monkeypatch.setitem(sys.modules, name, module)


def launched_process(file: str, given: dict[str, str]) -> Recorded:
    """The bridge's ExecuteProcess when ``file`` is launched with the arguments ``given``."""
    description = runpy.run_path(str(LAUNCH / file))["generate_launch_description"]()
    actions = description.args[0]
    declared = {
        a.args[0]: a.kwargs["default_value"] for a in actions if "default_value" in a.kwargs
    }
    assert set(declared) == REFERENCE
    (opaque,) = [a for a in actions if "function" in a.kwargs]
    (process,) = opaque.kwargs["function"]({**declared, **given}, *opaque.kwargs["args"])
    return process


def launched_command(file: str, given: dict[str, str]) -> list[str]:
    """The bridge's command line when ``file`` is launched with the arguments ``given``."""
    return launched_process(file, given).kwargs["cmd"]


@pytest.mark.parametrize(
    ("file", "bridge_input"),
    [("bridge_only.launch.py", "ros"), ("delivery_robot.launch.py", "sim")],
)
def test_launch_files_pass_the_reference_parameters(
    fake_launch, file: str, bridge_input: str
) -> None:
    command = launched_command(file, {"source_id": "launched-bot", "sample_rate_hz": "10.0"})
    assert command[:4] == ["phytrace-edge", "run", "--input", bridge_input]
    ros_args = command[command.index("--ros-args") + 1 :]
    assert ros_args == ["-p", "source_id:=launched-bot", "-p", "sample_rate_hz:=10.0"]
    loaded = settings_from_environment(None, {}, ros_params=ros_parameters(ros_args))
    assert loaded.settings.source_id == "launched-bot"
    assert loaded.settings.sample_rate_hz == 10.0
    assert loaded.origins["source_id"] == "ros param"
    assert loaded.origins["fleet_id"] == "default"  # not given: not passed at all


def test_no_arguments_means_no_ros_args(fake_launch) -> None:
    assert launched_command("bridge_only.launch.py", {}) == [
        "phytrace-edge",
        "run",
        "--input",
        "ros",
    ]


def test_under_systemd_the_bridge_takes_the_watchdog_over(
    fake_launch, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``ros2 launch`` is the unit's main process, so systemd's WATCHDOG_PID names it;
    the bridge gets the rest of the environment without it, and so sends the pings."""
    monkeypatch.setenv("WATCHDOG_PID", "4242")
    monkeypatch.setenv("WATCHDOG_USEC", "30000000")
    monkeypatch.setenv("NOTIFY_SOCKET", "/run/systemd/notify")
    env = launched_process("bridge_only.launch.py", {}).kwargs["env"]
    assert "WATCHDOG_PID" not in env
    assert env["WATCHDOG_USEC"] == "30000000" and env["NOTIFY_SOCKET"] == "/run/systemd/notify"
    from phytrace_edge.runtime.sd_notify import SystemdNotifier

    assert SystemdNotifier(env).watchdog_s == 30.0
    assert SystemdNotifier(dict(env, WATCHDOG_PID="4242")).watchdog_s is None  # as before
