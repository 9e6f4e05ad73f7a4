"""Queue: the durable SQLite WAL hand-off between build and ship, and the only code
that opens the queue file.

``store`` (QueueStore: put, claim, ack, release, renew) sits on ``database`` (the
connection, its lock, transactions, and the mapping of SQLite errors to queue errors),
with ``caps`` (the byte and event caps and what a full queue drops), ``leases``,
``maintenance`` (TTL expiry, space reclaim), ``inspect`` (the read-only snapshot
``status`` shows), ``service_state`` (the running service's heartbeat row),
``dead_letters``, ``codecs`` (at-rest encodings), ``migrate`` (schema versions),
``recovery`` (opening a file safely), ``options`` and ``records`` (value types).
"""
