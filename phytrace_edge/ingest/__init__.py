"""Ingest: ROS 2 messages -> plain readings, by pure per-topic handlers.

``handlers`` holds the conversion functions, ``topics`` the topic table, and
``dispatch`` the one place that calls handlers and counts what they reject.
"""
