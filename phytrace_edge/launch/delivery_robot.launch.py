"""phytrace-edge with the simulated delivery robot (no robot needed):

    ros2 launch phytrace_edge delivery_robot.launch.py \
        phycloud_endpoint:=http://localhost:8000/api/v1 source_id:=sim-robot-1

The simulated robot runs inside the bridge process on the mock ROS layer, so this works
on a machine with or without a ROS graph. The arguments are those of bridge_only.launch.py.
"""

import importlib.util
from pathlib import Path

from launch import LaunchDescription

_spec = importlib.util.spec_from_file_location(
    "bridge_only", Path(__file__).with_name("bridge_only.launch.py")
)
bridge_only = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bridge_only)


def generate_launch_description() -> LaunchDescription:
    return bridge_only.launch_description("sim")
