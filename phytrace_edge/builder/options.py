"""What the builder needs to know, and its defaults (the settings of the same names)."""

from __future__ import annotations

from dataclasses import dataclass

from phytrace_edge.builder.defaults import DEFAULT_SAMPLE_RATE_HZ, DEFAULT_STALE_AFTER_S


@dataclass(frozen=True)
class Identity:
    """Who the events are about (the UDM ``identity`` object)."""

    source_id: str
    source_type: str
    fleet_id: str | None = None
    site_id: str | None = None

    def as_dict(self) -> dict[str, str]:
        return {key: value for key, value in vars(self).items() if value is not None}


@dataclass(frozen=True)
class BuilderOptions:
    """SAMPLE_RATE_HZ, STALE_AFTER_S and USE_SIM_TIME, for one robot."""

    identity: Identity
    sample_rate_hz: float = DEFAULT_SAMPLE_RATE_HZ
    stale_after_s: float = DEFAULT_STALE_AFTER_S
    use_sim_time: bool = False
