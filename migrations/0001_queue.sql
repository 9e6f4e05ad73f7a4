-- 0001: the queue of events waiting for PhyCloud.
-- One row per event. Ids only grow, so a lease's id range never covers an event that
-- was put after it was taken: the store assigns them from the next_id counter, which
-- lives on the page every commit writes anyway (AUTOINCREMENT would add a page write
-- to every commit).

CREATE TABLE events (
    id         INTEGER PRIMARY KEY,
    event_id   TEXT    NOT NULL,          -- the UDM event_id, for idempotency and dead letters
    queued_at  REAL    NOT NULL,          -- unix seconds when put; TTL counts from here
    codec      INTEGER NOT NULL,          -- 0 none, 1 gzip, 2 zstd with dictionary
    dict_id    INTEGER,                   -- zstd_dictionaries.dict_id when codec = 2
    json_size  INTEGER NOT NULL,          -- bytes of the event's JSON (request sizing)
    body       BLOB    NOT NULL           -- the event's JSON, encoded by codec
);

-- A claim: the sender that holds it owns events first_id..last_id until expires_at.
CREATE TABLE leases (
    first_id   INTEGER PRIMARY KEY,
    last_id    INTEGER NOT NULL,
    owner      TEXT    NOT NULL,
    expires_at REAL    NOT NULL
);

-- Exact counters kept in the same transactions that change the queue, so status reads
-- them without scanning: depth, stored_bytes, queued_total, acked_total, dead_letters,
-- requeued_total, drop:<reason>.
CREATE TABLE counters (
    name  TEXT PRIMARY KEY,
    value INTEGER NOT NULL
) WITHOUT ROWID;

INSERT INTO counters(name, value) VALUES ('next_id', 1), ('depth', 0), ('stored_bytes', 0);

-- Every zstd dictionary a row was ever compressed with: rows stay readable after the
-- packaged dictionary changes.
CREATE TABLE zstd_dictionaries (
    dict_id  INTEGER PRIMARY KEY,
    content  BLOB NOT NULL,
    added_at REAL NOT NULL
);

-- Small facts for operators: the last quarantined file, and the like.
CREATE TABLE meta (
    key   TEXT PRIMARY KEY,
    value TEXT NOT NULL
) WITHOUT ROWID;
