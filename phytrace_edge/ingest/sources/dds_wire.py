"""The ``dds`` input's side of the wire: ROS 2's names on DDS, the configuration of the
input's domain (Fast DDS peers, loopback only), and the take loop that costs an
undecodable sample only itself (``take_each``). ``dds.py`` is the input.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

READER_DEPTH = 100
# a full-rate reader's samples wait for the next tick: 2 s of a 500 Hz topic at 5 Hz
# ticks is 200; the rest is room for a late tick
FULL_RATE_DEPTH = 1000
UNDECODABLE = "undecodable"  # the reject reason of a sample that cannot be decoded (as bag's)
# Fast DDS announces XTypes type information that Cyclone DDS rejects ("invalid type
# object"), and a reader whose writer's type cannot be resolved never matches: not one
# sample. With eProsima's information ignored (1.15 is its DDS vendor id), type names
# decide, as they do for rmw_cyclonedds, whose types carry no type information.
FAST_DDS_TYPES_BY_NAME = (
    "<Compatibility><IgnoreTypeInformation>1.15</IgnoreTypeInformation></Compatibility>"
)
LOCALHOST_ONLY = (
    "<General><Interfaces><NetworkInterface address='127.0.0.1'/></Interfaces>"
    "<AllowMulticast>false</AllowMulticast></General>"
    "<Discovery><ParticipantIndex>auto</ParticipantIndex>"
    "<MaxAutoParticipantIndex>64</MaxAutoParticipantIndex>"
    "<Peers><Peer address='localhost'/></Peers></Discovery>"
)


def domain_config(localhost_only: bool, cyclonedds_uri: str = "") -> str:
    """The Cyclone configuration of the input's domain: the user's ``CYCLONEDDS_URI``
    (kept: Cyclone merges a comma-separated list), then Fast DDS interoperability and,
    if asked, loopback only."""
    ours = (
        "<CycloneDDS><Domain id='any'>"
        + FAST_DDS_TYPES_BY_NAME
        + (LOCALHOST_ONLY if localhost_only else "")
        + "</Domain></CycloneDDS>"
    )
    return f"{cyclonedds_uri},{ours}" if cyclonedds_uri.strip() else ours


def dds_topic_name(ros_topic: str) -> str:
    """ROS 2's DDS name of a topic: ``/odom`` -> ``rt/odom``."""
    return "rt" + ros_topic


# What cyclonedds-python 11.0.1 does with a sample it cannot decode (measured on real
# Cyclone DDS: a std_msgs String whose CDR string holds 0xff 0xfe): ``take(N=k)``
# first takes up to k serialised samples out of the reader's cache in C, then decodes
# them in Python; a string that is not UTF-8 makes the decoding raise
# ``UnicodeDecodeError`` out of ``take``, and the k samples it took are gone, the good
# ones with the bad (a second ``take`` returns nothing). ``take(N=1)`` on the bad one
# raises the same and removes it: the next ``take(N=1)`` returns the sample after it.
# Only an error of the C take (``DDSException``) leaves the cache as it was.
# Cyclone calls a listener as each sample arrives (2,000 samples of a burst from
# another process: 2,000 calls, each finding one sample, even with a busy Python
# thread), so a batch is rare there; but an exception out of a listener is only
# printed by ctypes ("Exception ignored on calling ctypes callback function", with its
# traceback), the sample never counted; and out of the tick's take it ended the
# sampler thread, for each bad sample (its supervisor restarted it, logging an
# ERROR), and the topics after it were not taken. Hence one at a time, never
# raising: a failing take costs its one sample, counted ``undecodable``; the extra
# take that finds the cache empty costs a call into C.
def take_each(
    reader: Any,
    limit: int,
    on_sample: Callable[[Any], None],
    on_undecodable: Callable[[Exception], None],
    dds_error: type[Exception],
) -> None:
    """Take up to ``limit`` samples from ``reader`` one at a time, until it has no
    more: each to ``on_sample``, or, when it cannot be decoded, its exception to
    ``on_undecodable``. A ``dds_error`` (the C take failed: nothing was taken)
    propagates."""
    for _ in range(limit):
        try:
            samples = reader.take(N=1)
        except dds_error:
            raise
        except Exception as exc:  # raised while decoding: that sample is taken, and lost
            on_undecodable(exc)
            continue
        if not samples:
            return
        for sample in samples:
            on_sample(sample)
