"""Simulated sensors: the paper's 3-axis sensor, a lab's spreadsheet, six axes.

May import: the base modules, ``core``, ``data``, ``fitting`` and ``evaluation``;
no other top stage (``reporting``, ``logs``, ``fleet``, ``export``).
"""
