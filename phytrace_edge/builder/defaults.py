"""Defaults of the builder's settings (plain constants: the configuration reads them
without importing the stage)."""

DEFAULT_SAMPLE_RATE_HZ = 5.0
DEFAULT_STALE_AFTER_S = 5.0
