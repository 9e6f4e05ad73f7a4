"""phytrace-edge: the PhyTrace edge telemetry bridge.

ROS 2 topics -> ingest (pure handlers) -> builder (one UDM event per sample tick) ->
queue (durable SQLite WAL) -> ship (batched HTTP to PhyCloud).
"""

from __future__ import annotations

from typing import Any

from phytrace_edge._version import __version__

__all__ = ["__version__", "run_simulation"]


def run_simulation(num_ticks: int = 100, **kwargs: Any) -> dict[str, Any]:
    """Run the simulated delivery robot through the bridge; see
    ``phytrace_edge.runtime.simulation``."""
    from phytrace_edge.runtime.simulation import run_simulation as run

    return run(num_ticks, **kwargs)
