"""The simulated delivery robot, the mock rclpy layer it runs on, and ``run_simulation``."""

from phytrace_edge.sim.runner import run_simulation

__all__ = ["run_simulation"]
