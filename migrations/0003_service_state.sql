-- 0003: what the running service tells `phytrace-edge status` (another process):
-- one row, rewritten every heartbeat, with the sender's and the topics' figures.

CREATE TABLE service_state (
    id           INTEGER PRIMARY KEY CHECK (id = 1),
    heartbeat_at REAL    NOT NULL,    -- unix seconds of the last heartbeat
    running      INTEGER NOT NULL,    -- 1 while the service runs, 0 after a clean stop
    document     TEXT    NOT NULL     -- JSON: pid, version, sender and topic figures
);
