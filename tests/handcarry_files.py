"""Reading a hand-carry file of either format to its end or its first damage, for the
format tests."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from phytrace_edge.handcarry.format import DamagedExport
from phytrace_edge.handcarry.transfer import open_handcarry


def read_all(path: Path) -> tuple[list[dict[str, Any]], DamagedExport | None]:
    """The events read, and the damage that stopped the reading (None: a whole file)."""
    events: list[dict[str, Any]] = []
    try:
        for event in open_handcarry(path).events():
            events.append(event)
    except DamagedExport as damage:
        return events, damage
    return events, None
