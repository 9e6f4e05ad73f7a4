"""``bridge.health`` events: the bridge's own state, shipped through its own queue.

Every HEALTH_EVENT_INTERVAL_S, and at once when the health verdict changes (healthy
<-> unhealthy), the service turns the document ``status`` shows into an event. The
event waits in the queue like any other, so an outage's history (when the bridge went
unhealthy and why) reaches PhyCloud after the outage. Only figures and the problems'
text go out: the API key is never part of the status document.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from phytrace_edge.builder.envelope import envelope
from phytrace_edge.ingest.convert import present
from phytrace_edge.queue.peek import QueueStats
from phytrace_edge.runtime.health import Live, Thresholds, report
from phytrace_edge.runtime.status_documents import ServiceDocument, StatusReport
from phytrace_edge.udm.types import Built, HealthEvent, UdmIdentity, WallClock

EVENT_TYPE_HEALTH = "bridge.health"
PROBLEMS_MAX = 64
PROBLEM_MAX_CHARS = 512
TOPICS_MAX = 256


class HealthSchedule:
    """When a health event is due: ``trigger`` gives ``"change"``, ``"interval"`` or
    None for each verdict; the first verdict counts as a change (``start``)."""

    def __init__(self, interval_s: float) -> None:
        self.interval_s = interval_s
        self._healthy: bool | None = None
        self._last_at: float | None = None

    def trigger(self, healthy: bool, now_s: float) -> str | None:
        if not self.interval_s:
            return None
        if self._healthy is None:
            reason = "start"
        elif healthy != self._healthy:
            reason = "change"
        elif self._last_at is not None and now_s - self._last_at >= self.interval_s:
            reason = "interval"
        else:
            return None
        self._healthy, self._last_at = healthy, now_s
        return reason


def health_event(
    identity: UdmIdentity,
    report: StatusReport,
    trigger: str,
    uptime_s: float,
    captured_at_s: float,
) -> HealthEvent:
    """One ``bridge.health`` event from a status document (``health.report``)."""
    queue = report["queue"]
    event: HealthEvent = {
        **envelope(identity, EVENT_TYPE_HEALTH, captured_at_s),
        "trigger": trigger,
        "healthy": bool(report["healthy"]),
        "problems": [p[:PROBLEM_MAX_CHARS] for p in report["problems"][:PROBLEMS_MAX]],
        "version": str(report["service"].get("version", "")),
        "uptime_s": round(max(0.0, uptime_s), 1),
        "queue": present(
            depth=queue["depth"],
            bytes=queue["bytes"],
            fill=queue["fill"],
            oldest_age_s=None if queue["oldest_age_s"] is None else max(0, queue["oldest_age_s"]),
        ),
        "drops": dict(report["drops"]),
        "dead_letters": report["dead_letters"],
        "send_rate_eps": report["send_rate_eps"],
        "events_sent": report["sent_total"],
        "retries": report["retries"],
        "thread_restarts": dict(report["thread_restarts"]),
        "topics": {
            topic: _topic(figures) for topic, figures in list(report["topics"].items())[:TOPICS_MAX]
        },
    }
    incidents = report.get("incidents", {})
    if incidents.get("enabled"):
        event["incidents"] = {
            "recorded": incidents.get("recorded", 0),
            "parts": incidents.get("parts", 0),
            "parts_sent": incidents.get("parts_sent", 0),
            "rate_limited": incidents.get("rate_limited", 0),
            "samples_dropped": incidents.get("samples_dropped", 0),
        }
    last_error_class = report.get("last_error_class")
    if last_error_class:
        event["last_error_class"] = last_error_class
    clock = report["clock"]
    wall_clock = WallClock()  # the machine's clock, as the queue last saw it
    if clock["synchronized"] is not None:
        wall_clock["synchronized"] = clock["synchronized"]
    if clock["last_step_s"] is not None:
        wall_clock["last_step_s"] = clock["last_step_s"]
    if clock["last_step_at"] is not None:
        wall_clock["last_step_at"] = clock["last_step_at"]
    if wall_clock:
        event["wall_clock"] = wall_clock
    return event


def _topic(figures: Mapping[str, Any]) -> dict[str, Any]:
    age = figures.get("last_seen_age_s")
    return present(
        received=figures.get("received", 0),
        rate_hz=figures.get("rate_hz", 0.0),
        last_seen_age_s=None if age is None else max(0.0, age),
        rejected=sum(figures.get("rejected", {}).values()),
        publishers=figures.get("publishers"),
        qos_incompatible=figures.get("qos_incompatible"),
    )


class HealthEvents:
    """Emits a ``bridge.health`` event when one is due (see the module doc)."""

    def __init__(
        self,
        interval_s: float,
        thresholds: Thresholds | None,
        identity: UdmIdentity,
        started_at: float,
        emit: Callable[[Built], None],
    ) -> None:
        self._schedule = HealthSchedule(interval_s if thresholds is not None else 0.0)
        self._thresholds = thresholds
        self._identity = identity.copy()
        self._started_at = started_at
        self._emit = emit

    def emit_if_due(
        self,
        stats: QueueStats,
        now: float,
        trigger: str | None = None,
        live: ServiceDocument | None = None,
    ) -> None:
        """An event when the schedule says so, or now with ``trigger`` (``stop``);
        ``live`` is the service's document of this moment."""
        if self._thresholds is None or not self._schedule.interval_s:
            return
        heard = None if live is None else Live(live, 0.0)
        document = report(stats, self._thresholds, now, heard)
        trigger = self._schedule.trigger(document["healthy"], now) if trigger is None else trigger
        if trigger is not None:
            captured_at = now + stats.clock.wall_offset  # an event's time is a date
            event = health_event(
                self._identity, document, trigger, now - self._started_at, captured_at
            )
            self._emit(Built(event, important=trigger != "interval"))
