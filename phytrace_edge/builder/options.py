"""What the builder needs to know, and its defaults (the settings of the same names)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from phytrace_edge.builder.defaults import (
    DEFAULT_ROSOUT_BURST,
    DEFAULT_ROSOUT_MIN_LEVEL,
    DEFAULT_SAMPLE_RATE_HZ,
    DEFAULT_STALE_AFTER_S,
)
from phytrace_edge.ingest.defaults import DEFAULT_EXTRA_MAX_ARRAY
from phytrace_edge.ingest.topics import ExtraTopic

if TYPE_CHECKING:  # the types module costs every command's start: annotations only
    from phytrace_edge.udm.types import UdmIdentity


@dataclass(frozen=True)
class Identity:
    """Who the events are about (the UDM ``identity`` object)."""

    source_id: str
    source_type: str
    fleet_id: str | None = None
    site_id: str | None = None

    def as_dict(self) -> UdmIdentity:
        identity: UdmIdentity = {"source_id": self.source_id, "source_type": self.source_type}
        if self.fleet_id is not None:
            identity["fleet_id"] = self.fleet_id
        if self.site_id is not None:
            identity["site_id"] = self.site_id
        return identity


@dataclass(frozen=True)
class BuilderOptions:
    """SAMPLE_RATE_HZ, STALE_AFTER_S, USE_SIM_TIME, TOPICS_EXTRA and the /rosout
    settings, for one robot."""

    identity: Identity
    sample_rate_hz: float = DEFAULT_SAMPLE_RATE_HZ
    stale_after_s: float = DEFAULT_STALE_AFTER_S
    use_sim_time: bool = False
    extra_topics: tuple[ExtraTopic, ...] = ()
    extra_max_array: int = DEFAULT_EXTRA_MAX_ARRAY
    rosout_min_level: str = DEFAULT_ROSOUT_MIN_LEVEL
    rosout_burst: int = DEFAULT_ROSOUT_BURST
