"""Calibration sets in: reading, layouts, units and zero correction.

A calibration set (one CSV per repetition, or one lab spreadsheet) becomes a
zero-corrected :class:`~fsdecouple.data.calibration.CalibrationSet` (Section 3);
``init`` guesses a config from a file's columns.

May import: the base modules and ``core``.
"""
