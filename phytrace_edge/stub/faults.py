"""Fault injection of the dev stub: what to do to the next POST /events.

Set at start (``phytrace-edge stub --error-rate 0.2 ...``) and changed at run time
with ``PUT /api/v1/faults``. Decisions are drawn from a seeded RNG so a test can
reproduce a run.
"""

from __future__ import annotations

import random
from dataclasses import asdict, dataclass, fields, replace
from typing import Any


@dataclass(frozen=True)
class Faults:
    error_rate: float = 0.0
    error_status: int = 503
    fixed_status: int | None = None
    retry_after: str | None = None
    latency_s: float = 0.0
    drop_rate: float = 0.0
    partial_rejects: bool = False

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)

    def updated(self, changes: dict[str, Any]) -> Faults:
        """A copy with ``changes`` applied; raises ValueError naming a bad field."""
        known = {f.name for f in fields(self)}
        for key in changes:
            if key not in known:
                raise ValueError(f"unknown fault setting {key!r}")
        faults = replace(self, **changes)
        faults.check()
        return faults

    def check(self) -> None:
        for name in ("error_rate", "drop_rate"):
            value = getattr(self, name)
            if (
                isinstance(value, bool)
                or not isinstance(value, (int, float))
                or not 0 <= value <= 1
            ):
                raise ValueError(f"{name} must be a number from 0 to 1")
        for name in ("error_status", "fixed_status"):
            value = getattr(self, name)
            if value is None and name == "fixed_status":
                continue
            if isinstance(value, bool) or not isinstance(value, int) or not 400 <= value <= 599:
                raise ValueError(f"{name} must be an HTTP status from 400 to 599")
        latency = self.latency_s
        if (
            isinstance(latency, bool)
            or not isinstance(latency, (int, float))
            or not 0 <= latency <= 60
        ):
            raise ValueError("latency_s must be a number of seconds from 0 to 60")
        if self.retry_after is not None and not isinstance(self.retry_after, str):
            raise ValueError("retry_after must be a string (seconds or an HTTP-date) or null")
        if not isinstance(self.partial_rejects, bool):
            raise ValueError("partial_rejects must be true or false")


@dataclass(frozen=True)
class Decision:
    """What to do with one request: answer ``status`` now, drop it, or process it."""

    status: int | None = None
    drop: bool = False


def decide(faults: Faults, rng: random.Random) -> Decision:
    if faults.fixed_status is not None:
        return Decision(status=faults.fixed_status)
    if faults.error_rate and rng.random() < faults.error_rate:
        return Decision(status=faults.error_status)
    if faults.drop_rate and rng.random() < faults.drop_rate:
        return Decision(drop=True)
    return Decision()
