-- 0007: incidents first. An `incident` event (UDM 1.3.0: full-rate data around a
-- trigger) is stored with important = 2: never thinned, like every important event,
-- and sent before the rest of any backlog, whatever hour it was queued in
-- (queue/outbound/claims.py). Found by this index, not a scan.

CREATE INDEX events_incident ON events(id) WHERE important = 2;
