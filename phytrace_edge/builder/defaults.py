"""Defaults of the builder's settings (plain constants: the configuration reads them
without importing the stage)."""

DEFAULT_SAMPLE_RATE_HZ = 5.0
DEFAULT_STALE_AFTER_S = 5.0
ROSOUT_LEVELS = ("debug", "info", "warn", "error", "fatal")
DEFAULT_ROSOUT_MIN_LEVEL = "warn"
DEFAULT_ROSOUT_BURST = 20  # records per logger per minute; the rest are counted
