"""Defaults of the ingest settings (plain constants: the configuration reads them
without importing the stage)."""

DEFAULT_REPLAY_RATE = 1.0  # a bag at its recorded speed
DEFAULT_EXTRA_MAX_ARRAY = 256  # longer arrays of an extra topic become {len, head}
