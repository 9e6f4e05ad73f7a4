-- 0002: events PhyCloud rejected for good, kept for inspection, export and requeue.

CREATE TABLE dead_letters (
    id          INTEGER PRIMARY KEY AUTOINCREMENT,
    event_id    TEXT    NOT NULL,
    queued_at   REAL    NOT NULL,
    dead_at     REAL    NOT NULL,
    reason      TEXT    NOT NULL,         -- e.g. "rejected: 422", "too_large"
    status_code INTEGER,                  -- HTTP status of the rejection, when there was one
    response    TEXT,                     -- what PhyCloud said (cut to 4 KiB)
    codec       INTEGER NOT NULL,
    dict_id     INTEGER,
    json_size   INTEGER NOT NULL,
    body        BLOB    NOT NULL
);

CREATE INDEX dead_letters_dead_at ON dead_letters (dead_at);
