-- 0005: event classes and thinning. `important` marks an event the builder said must
-- never be thinned (an alarm, a transition, a new goal, the first data after a gap);
-- such a row is never packed into a frame. `thin_level` is how often a periodic row was
-- halved: its events are 1 in 2^thin_level of those put (queue/thinning.py). The table
-- is rebuilt so that the small columns stay before the body: a query on them never
-- reads a frame's overflow pages.

CREATE TABLE events_v5 (
    id         INTEGER PRIMARY KEY,
    last_id    INTEGER NOT NULL,
    count      INTEGER NOT NULL DEFAULT 1,
    important  INTEGER NOT NULL DEFAULT 0,  -- 1: never thinned, first in the backfill
    thin_level INTEGER NOT NULL DEFAULT 0,  -- 1 in 2^thin_level of the periodic events kept
    queued_at  REAL    NOT NULL,
    newest_at  REAL,
    event_id   TEXT    NOT NULL,
    codec      INTEGER NOT NULL,
    dict_id    INTEGER,
    json_size  INTEGER NOT NULL,
    body       BLOB    NOT NULL
);

INSERT INTO events_v5(id, last_id, count, queued_at, newest_at, event_id, codec, dict_id,
                      json_size, body)
    SELECT id, last_id, count, queued_at, newest_at, event_id, codec, dict_id, json_size, body
    FROM events;
DROP TABLE events;
ALTER TABLE events_v5 RENAME TO events;

-- the backfill takes important events first: found without a scan
CREATE INDEX events_important ON events(id) WHERE important = 1;
