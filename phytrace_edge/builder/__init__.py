"""Build: latest readings -> one UDM event per sample tick.

``options`` (identity, rates), ``builder`` (UDMBuilder: the latest values and what
happens between two ticks, thread-safe), ``assemble`` (one event, pure),
``log_records`` and ``topic_events`` (the side events) and ``sampler`` (the tick loop
every input shares).
"""
