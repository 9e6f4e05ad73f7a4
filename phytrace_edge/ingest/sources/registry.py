"""Sources by name, imported only when chosen (rclpy, cyclonedds and rosbags are
optional extras): ``create_source(options)``."""

from __future__ import annotations

import importlib

from phytrace_edge.errors import ConfigError
from phytrace_edge.ingest.sources.base import Source, SourceOptions

SOURCES = {
    "sim": "phytrace_edge.ingest.sources.sim:SimSource",
    "ros": "phytrace_edge.ingest.sources.ros:RosSource",
    "dds": "phytrace_edge.ingest.sources.dds:DdsSource",
    "bag": "phytrace_edge.ingest.sources.bag:BagSource",
}


def create_source(options: SourceOptions) -> Source:
    """The source ``options.kind`` names."""
    target = SOURCES.get(options.kind)
    if target is None:
        raise ConfigError(f"BRIDGE_INPUT={options.kind!r}: must be ros, dds, sim or bag:PATH")
    module, _, name = target.partition(":")
    source: Source = getattr(importlib.import_module(module), name)(options)
    return source
