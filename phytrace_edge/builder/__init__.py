"""Build: latest readings -> one UDM event per sample tick.

``options`` (identity, rates), ``builder`` (UDMBuilder: latest values, thread-safe),
``accumulate`` (what happens between two ticks), ``assemble`` (one event, pure) and
``sampler`` (the tick loop every input shares).
"""
