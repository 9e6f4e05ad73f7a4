-- 0006: queue time (queue/clock.py). Every time the queue stores from now on (queued_at,
-- newest_at, a lease's expires_at, the heartbeat) is queue time: CLOCK_BOOTTIME plus the
-- base of the boot it was taken in, which never steps with the wall clock. Times
-- written before this migration are wall-clock seconds, which queue time continues
-- from.

-- One row per boot that opened the queue: queue time = CLOCK_BOOTTIME + base.
CREATE TABLE clock (
    boot_id TEXT PRIMARY KEY,
    base    REAL NOT NULL
) WITHOUT ROWID;

-- Steps of the wall clock seen while the queue was open: at (queue time), by how much
-- (seconds, + forward), in which boot. Events stamped before a step are repaired by it.
CREATE TABLE clock_steps (
    at      REAL PRIMARY KEY,
    step_s  REAL NOT NULL,
    boot_id TEXT NOT NULL
);
