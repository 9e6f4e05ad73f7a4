"""What ``status`` shows of the incident recorder: a type only, light enough for the
``status`` command's start (it imports nothing of the recorder)."""

from __future__ import annotations

from typing import TypedDict


class IncidentFigures(TypedDict, total=False):
    """The recorder's figures (``status``'s ``incidents``): triggers seen, and what
    became of them (opened, extended an open window, rate_limited); incidents recorded
    (cut_short: by a stop) and their parts queued; the window's buffer and the samples
    its byte bound pushed out. The sender adds the parts PhyCloud took
    (``parts_sent``) or refused for good (``parts_dead_lettered``)."""

    enabled: bool
    recording: bool
    window_topics: list[str]
    buffer_bytes: int
    buffer_max_bytes: int
    buffer_samples: int
    samples_dropped: int
    triggers: int
    opened: int
    extended: int
    rate_limited: int
    recorded: int
    cut_short: int
    parts: int
    parts_sent: int
    parts_dead_lettered: int
