"""Queue: the durable SQLite WAL hand-off between build and ship, and the only code
that opens the queue file.

``store`` (QueueStore: put, claim, ack, release, renew) is the front; ``appender`` is
its put path, ``records`` and ``options`` its value types and limits. Behind it, one
package per concept:

- ``storage``: the file itself (its connection and lock, opening it safely,
  migrations, SQLite's errors, rows and counters, the heartbeat row, the file watch);
- ``space``: room on the disk (caps, thinning, a full volume, the reserve, the volume's
  free space, TTL upkeep);
- ``encoding``: events at rest (codecs, dictionaries, frames);
- ``timekeeping``: queue time and the repair of stamps after a clock step;
- ``outbound``: the sending side (claims, leases, ownership, dead letters).

``peek`` reads what ``status`` shows without the writer's side (no store opened).
"""
