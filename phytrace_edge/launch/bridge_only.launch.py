"""phytrace-edge attached to a running robot: ``ros2 launch <this file> name:=value ...``.

    ros2 launch bridge_only.launch.py phycloud_endpoint:=https://api.phycloud.phyware.io/v1 \
        source_id:=my-robot-1 source_type:=amr fleet_id:=my-fleet sample_rate_hz:=10.0

Every argument becomes a ROS parameter of the same name as the setting (docs/configuration.md),
below flags, environment and config file in precedence. Prefer PHYCLOUD_API_KEY in the
environment to phycloud_api_key:=...: process arguments are visible to every user of the robot.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, ExecuteProcess, OpaqueFunction
from launch.substitutions import LaunchConfiguration

# the reference guide's launch parameters, with their defaults ("" = not set)
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


def bridge_command(bridge_input: str, values: dict) -> list:
    """``phytrace-edge run`` with each argument that was given as ``-p name:=value``. An
    unset one is left out: rcl refuses an empty ``-p name:=`` and the bridge would not
    start, so any subset of the arguments works."""
    parameters = []
    for name in ARGUMENTS:
        if values.get(name):
            parameters += ["-p", f"{name}:={values[name]}"]
    command = ["phytrace-edge", "run", "--input", bridge_input]
    return command + (["--ros-args", *parameters] if parameters else [])


def bridge_process(context, bridge_input: str) -> list:
    """The bridge's process, built once the arguments' values are known."""
    values = {name: LaunchConfiguration(name).perform(context) for name in ARGUMENTS}
    command = bridge_command(bridge_input, values)
    return [ExecuteProcess(cmd=command, output="screen", sigterm_timeout="20")]


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
