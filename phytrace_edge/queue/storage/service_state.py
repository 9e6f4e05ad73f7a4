"""The running service's heartbeat: one row of the queue database, rewritten every few
seconds with the service's figures, that ``status`` reads from another process. The row
survives the process, so ``status`` can say when the service last lived and what it
last saw, whether or not it runs now."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import orjson

from phytrace_edge.queue.storage.database import Database


def write_service_state(
    db: Database, document: Mapping[str, Any], running: bool, now: float, durable: bool = True
) -> None:
    row = (now, int(running), orjson.dumps(document).decode())
    db.write(
        lambda cursor: cursor.execute(
            "INSERT OR REPLACE INTO service_state(id, heartbeat_at, running, document) "
            "VALUES (1, ?, ?, ?)",
            row,
        ),
        durable,
    )
