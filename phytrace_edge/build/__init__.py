"""Build: latest readings -> one UDM event per sample tick."""

from phytrace_edge.build.builder import Clock, Identity, SystemClock, UDMBuilder

__all__ = ["Clock", "Identity", "SystemClock", "UDMBuilder"]
