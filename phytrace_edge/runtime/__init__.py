"""The running service: the pipeline assembled (``wiring``), its threads supervised,
the queue writer, the heartbeat and health, status documents, logs and metrics."""
