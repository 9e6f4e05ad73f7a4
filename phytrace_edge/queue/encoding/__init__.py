"""How events are kept at rest: per-event codecs (gzip, zstd, zstd with a dictionary),
the dictionaries, and frames (an outage's events compressed together).
"""
