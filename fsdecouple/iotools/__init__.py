"""File formats: calibration sets, voltage logs, atomic output."""
