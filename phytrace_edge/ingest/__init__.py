"""Ingest: ROS 2 messages -> readings (plain typed dicts).

``topics`` is the topic table, ``handlers`` one pure function per topic (``convert``
their shared conversions), ``dispatch`` calls them and counts rejects, ``qos`` picks a
subscription's QoS, and ``sources/`` are the inputs: the simulator, rclpy, Cyclone DDS
and bag replay, behind one protocol.
"""
