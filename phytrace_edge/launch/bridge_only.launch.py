"""phytrace-edge attached to a running robot: ``ros2 launch phytrace_edge
bridge_only.launch.py name:=value ...`` (or the path of this file, for a pip install).

    ros2 launch phytrace_edge bridge_only.launch.py \
        phycloud_endpoint:=https://api.phycloud.phyware.io/v1 \
        source_id:=my-robot-1 source_type:=amr fleet_id:=my-fleet sample_rate_hz:=10.0

Every argument becomes a ROS parameter of the same name as the setting (docs/configuration.md),
below flags, environment and config file in precedence. Prefer PHYCLOUD_API_KEY in the
environment to phycloud_api_key:=...: process arguments are visible to every user of the robot.
"""

import os
from pathlib import Path

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, ExecuteProcess, OpaqueFunction
from launch.substitutions import LaunchConfiguration

# the launch parameters of the product's original description (docs/ros2.md, "Launch
# files"), with their defaults ("" = not set)
ARGUMENTS = {
    "phycloud_endpoint": ("", "PhyCloud ingestion API base URL"),
    "phycloud_api_key": ("", "API key (prefer the PHYCLOUD_API_KEY environment variable)"),
    "source_id": ("", "unique robot id"),
    "source_type": ("", "delivery_robot, amr, agv, drone, humanoid or arm"),
    "fleet_id": ("", "fleet grouping id"),
    "site_id": ("", "site or facility id"),
    "sample_rate_hz": ("", "UDM events built per second"),
    "batch_size": ("", "events per HTTP request"),
}
BRIDGE_INPUT = "ros"


def bridge_executable() -> str:
    """``phytrace-edge`` as the ROS package installs it (colcon: ``lib/phytrace_edge``
    under the package's prefix), else, for a pip install, the one on PATH."""
    try:
        from ament_index_python.packages import get_package_prefix

        prefix = get_package_prefix("phytrace_edge")
    except (ImportError, LookupError):  # PackageNotFoundError is a KeyError
        return "phytrace-edge"
    return str(Path(prefix) / "lib" / "phytrace_edge" / "phytrace-edge")


def bridge_command(bridge_input: str, values: dict) -> list:
    """``phytrace-edge run`` with each argument that was given as ``-p name:=value``. An
    unset one is left out: rcl refuses an empty ``-p name:=`` and the bridge would not
    start, so any subset of the arguments works."""
    parameters = []
    for name in ARGUMENTS:
        if values.get(name):
            parameters += ["-p", f"{name}:={values[name]}"]
    command = [bridge_executable(), "run", "--input", bridge_input]
    return command + (["--ros-args", *parameters] if parameters else [])


def bridge_environment(environment: dict) -> dict:
    """The bridge's environment: launch's own, less ``WATCHDOG_PID``. Under systemd
    with the drop-in ``systemd/phytrace-edge.service.d/ros2-launch.conf.example``,
    ``ros2 launch`` is the main process, so systemd names it there; the bridge, which
    alone knows whether it makes progress, takes the watchdog over (the drop-in's
    ``NotifyAccess=all`` accepts its pings)."""
    return {name: value for name, value in environment.items() if name != "WATCHDOG_PID"}


def bridge_process(context, bridge_input: str) -> list:
    """The bridge's process, built once the arguments' values are known."""
    values = {name: LaunchConfiguration(name).perform(context) for name in ARGUMENTS}
    command = bridge_command(bridge_input, values)
    return [
        ExecuteProcess(
            cmd=command,
            env=bridge_environment(dict(os.environ)),
            output="screen",
            sigterm_timeout="20",
        )
    ]


def launch_description(bridge_input: str) -> LaunchDescription:
    return LaunchDescription(
        [
            *(
                DeclareLaunchArgument(name, default_value=default, description=doc)
                for name, (default, doc) in ARGUMENTS.items()
            ),
            OpaqueFunction(function=bridge_process, args=[bridge_input]),
        ]
    )


def generate_launch_description() -> LaunchDescription:
    return launch_description(BRIDGE_INPUT)
