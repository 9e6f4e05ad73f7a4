"""Which QoS a subscription asks for, decided from what the publishers offer. Pure."""

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


def matching_qos(offered: list[tuple[bool, bool]]) -> QosChoice:
    """The QoS that receives from every publisher (the rule rosbag2 and foxglove_bridge
    use): reliable only when every publisher is reliable, transient local only when
    every publisher is. ``offered`` holds (reliable, transient_local) per publisher."""
    return QosChoice(
        reliable=bool(offered) and all(reliable for reliable, _ in offered),
        transient_local=bool(offered) and all(latched for _, latched in offered),
    )
