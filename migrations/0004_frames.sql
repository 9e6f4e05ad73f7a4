-- 0004: frames. A row holds `count` events: one for a fresh event, up to a hundred for a
-- frame, the events of an outage compressed together (queue/frames.py). A row covers
-- the ids id .. last_id; no two rows' ranges overlap, so leases (id ranges) hold whole
-- rows. The small columns come before the body, so queries that look only at ids,
-- counts and times never read a frame's overflow pages.

CREATE TABLE events_v4 (
    id         INTEGER PRIMARY KEY,
    last_id    INTEGER NOT NULL,           -- the last id the row covers (id, for one event)
    count      INTEGER NOT NULL DEFAULT 1, -- events in the row
    queued_at  REAL    NOT NULL,           -- unix seconds its first event was put
    newest_at  REAL,                       -- when its last event was put (frames; TTL)
    event_id   TEXT    NOT NULL,           -- the UDM event_id (a frame's: its first)
    codec      INTEGER NOT NULL,           -- 0 none, 1 gzip, 2 zstd with dictionary
    dict_id    INTEGER,                    -- zstd_dictionaries.dict_id when codec = 2
    json_size  INTEGER NOT NULL,           -- bytes of JSON of all its events
    body       BLOB    NOT NULL            -- the JSON, encoded by codec; a frame's events
                                           -- are joined by newlines before encoding
);

INSERT INTO events_v4(id, last_id, count, queued_at, event_id, codec, dict_id, json_size, body)
    SELECT id, id, 1, queued_at, event_id, codec, dict_id, json_size, body FROM events;
DROP TABLE events;
ALTER TABLE events_v4 RENAME TO events;
