"""Many sensors: ``fit-many`` over a directory of sensors, ``compare`` and drift.

May import: the base modules, ``core``, ``data``, ``fitting`` and ``evaluation``;
no other top stage (``reporting``, ``logs``, ``export``, ``sim``).
"""
