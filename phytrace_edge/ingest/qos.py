"""Which QoS a subscription asks for, decided from what the publishers offer. Pure.

The ``ros`` and ``dds`` inputs follow the same rules (docs/ros2.md): before a topic's
publishers are known, ``before_publishers``; once they are, ``matching_qos``; what a
choice cannot match, ``incompatible``."""

from typing import NamedTuple


class QosChoice(NamedTuple):
    """What a subscription asks for: the part of QoS that decides matching."""

    reliable: bool
    transient_local: bool

    def describe(self) -> str:
        return (
            f"{'reliable' if self.reliable else 'best effort'}, "
            f"{'transient local' if self.transient_local else 'volatile'}"
        )


# Before a topic's publisher is seen, the bridge listens anyway, so that nothing
# published before the next look at the graph is lost. State streams: best effort,
# which matches every publisher (their next message comes soon anyway). Topics where
# every message counts (diagnostics, goals, a task's state, /rosout): reliable, as their
# publishers are, because only a reliable pair recovers a message published the moment
# the publisher matched, before the bridge's side had matched it (measured on Fast DDS:
# 2 of 12 such one-shot ERRORs lost to a best-effort subscription; on Cyclone DDS, 1
# and 5 of 12).
ANY_PUBLISHER = QosChoice(reliable=False, transient_local=False)
RELIABLE_PUBLISHER = QosChoice(reliable=True, transient_local=False)


def before_publishers(every_message: bool) -> QosChoice:
    """What a topic is listened to with while none of its publishers is known."""
    return RELIABLE_PUBLISHER if every_message else ANY_PUBLISHER


def matching_qos(offered: list[tuple[bool, bool]]) -> QosChoice:
    """The QoS that receives from every publisher (the rule rosbag2 and foxglove_bridge
    use): reliable only when every publisher is reliable, transient local only when
    every publisher is. ``offered`` holds (reliable, transient_local) per publisher."""
    return QosChoice(
        reliable=bool(offered) and all(reliable for reliable, _ in offered),
        transient_local=bool(offered) and all(latched for _, latched in offered),
    )


def incompatible(choice: QosChoice, offered: list[tuple[bool, bool]]) -> int:
    """How many of the ``offered`` publishers a subscription asking for ``choice``
    cannot match: a reliable or transient-local request meets a best-effort or
    volatile offer."""
    return sum(
        (choice.reliable and not reliable) or (choice.transient_local and not latched)
        for reliable, latched in offered
    )
