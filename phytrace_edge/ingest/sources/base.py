"""What every input has in common: its options, where it delivers, and its protocol.

A source turns the outside world into ``(topic, message)`` calls of ``Feed.on_message``
as messages arrive, and, at the sample tick, into what ``Source.before_tick`` returns
(the newest samples of the state topics, as ``dispatch.Take`` values, which the sampler
hands to the dispatcher); it never builds events itself. The one tick loop
(``builder.sampler``) builds them: in a thread of its own for live inputs, or called
through ``Feed.tick`` by an input that keeps its own time (a bag on its timeline, the
simulator in virtual time).

A feed may also take a mark (``Feed.mark``): an incident's trigger by hand, which an
input that can serve one (the ``ros`` input's ``~/mark`` service) hands over with a
reason, answered with a ``MarkReply``; the data still flows one way, into the pipeline.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

from phytrace_edge.ingest.defaults import DEFAULT_REPLAY_RATE
from phytrace_edge.ingest.qos import QosChoice

if TYPE_CHECKING:  # the dispatcher costs every command's start: annotations only
    from phytrace_edge.ingest.dispatch import Take

NODE_NAME = "phytrace_edge"


@dataclass(frozen=True)
class SourceOptions:
    """BRIDGE_INPUT and the ingest settings, as plain values."""

    kind: str  # "sim", "ros", "dds" or "bag"
    topics: Mapping[str, str]  # canonical topic -> name subscribed on the robot
    # TOPICS_EXTRA: name -> (name subscribed on the robot, type or "" for the graph's)
    extra_topics: Mapping[str, tuple[str, str]] = field(default_factory=dict)
    qos_overrides: Mapping[str, QosChoice] = field(default_factory=dict)
    # topics delivered on every message as they come, never only taken at the tick: an
    # incident's trigger topics (canonical or TOPICS_EXTRA names)
    every_message: frozenset[str] = frozenset()
    # topics of which every message counts, but not at once: an incident's window
    # topics, all their messages taken at the tick (the ros and dds inputs; the bag
    # input delivers every message anyway)
    full_rate: frozenset[str] = frozenset()
    bag_path: str = ""
    replay_rate: float = DEFAULT_REPLAY_RATE
    ros_args: tuple[str, ...] = ()  # after --ros-args: remaps, log levels, parameters
    # the effective settings, declared read-only on the rclpy node: name -> (value, doc)
    parameters: Mapping[str, tuple[Any, str]] = field(default_factory=dict)
    dds_domain_id: int = 0
    dds_localhost_only: bool = False
    dds_cyclonedds_uri: str = ""  # the user's Cyclone configuration, kept by the dds input
    seed: int = 0  # of the simulated world
    virtual_time: bool = False  # the simulator only: run as fast as possible
    max_ticks: int | None = None  # the simulator only: stop after this many robot cycles


def _ignore_unreadable(topic: str, reason: str, detail: str) -> None:
    """A feed that does not count what its source could not decode."""


def always_due(topic: str) -> bool:
    """A feed with no pace of its own for any topic."""
    return True


class OnMessage(Protocol):
    """Where a source hands one message of a (canonical) topic, with how long ago it
    was received when that was not just now (a message taken at the sample tick)."""

    def __call__(self, topic: str, msg: Any, age_s: float = 0.0) -> None: ...


@dataclass(frozen=True)
class MarkReply:
    """The answer to a mark: whether an incident records it (opened or extended), and
    what to tell the caller (the incident's id, or why nothing is recorded)."""

    accepted: bool
    message: str


@dataclass(frozen=True)
class Feed:
    """Where a source delivers: each message, and (for sources that keep their own
    time) each sample tick with its ``captured_at`` (None = the wall clock); a tick
    says whether it built an event (False: nothing fresh to report). A message the
    source could not decode goes to ``on_unreadable`` (topic, reason, detail), to be
    counted with the topic's rejects. ``due`` says whether a ``TOPICS_EXTRA`` topic
    is due now (its ``rate_hz``): a source that takes messages at the tick takes an
    extra topic's only then, so a topic sent once a second is not deserialised at
    every tick. ``mark`` (None: no marks through the input) takes a mark by hand with
    its reason and says what became of it; it may be called on any thread."""

    on_message: OnMessage
    tick: Callable[[float | None], bool]
    sample_period_s: float
    on_unreadable: Callable[[str, str, str], None] = _ignore_unreadable
    due: Callable[[str], bool] = always_due
    mark: Callable[[str], MarkReply] | None = None


def age_at_take(received_ns: int, now_ns: int, waited_s: float) -> float:
    """How old a message taken now is, in seconds: from its reception stamp
    (``received_ns``, on the same wall clock as ``now_ns``; 0 when the middleware
    gives none: then 0.0, as if received now). Never more than ``waited_s``, the time
    since the subscription was last emptied (its previous take, or its creation):
    a reader that keeps one message cannot hold one from before. That bound also
    keeps a writer's stamp from another machine's clock (the fallback when the
    middleware has no reception stamp) from making a fresh message look stale."""
    if received_ns <= 0:
        return 0.0
    return min(max(0.0, (now_ns - received_ns) / 1e9), max(0.0, waited_s))


class SourceClock(Protocol):
    """The builder's clock, when a source keeps its own time."""

    def monotonic(self) -> float: ...

    def wall(self) -> float: ...


@dataclass(frozen=True)
class Finished:
    """What a finite source (a bag) did, in one line, and whether it read to the end."""

    text: str
    ok: bool


class Source(Protocol):
    """One input. ``start`` opens it (a clear ConfigError when it cannot be), ``run``
    is its loop (supervised: restarted when it raises; returning means a finite input
    is exhausted), ``stop`` releases it. ``before_tick`` runs on the sample tick,
    before its event is built: it takes the newest sample of each state topic the
    input reads at the tick and returns them, in order, calling nothing back (the
    sampler hands them to the dispatcher); an input that takes nothing returns []."""

    keeps_time: bool
    clock: SourceClock | None

    def field_types(self, msg: Any) -> Mapping[str, str]:
        """The rosidl field types of one of this input's messages (``ingest.generic``)."""
        ...

    def start(self, feed: Feed) -> None: ...

    def run(self, stop: threading.Event, beat: Callable[[], None]) -> None: ...

    def before_tick(self) -> Sequence[Take]: ...

    def stop(self) -> None: ...

    def finished(self) -> Finished | None: ...

    def topic_stats(self) -> dict[str, dict[str, Any]]: ...
