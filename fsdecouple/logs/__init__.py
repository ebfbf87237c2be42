"""Decoupling logs: ``apply`` on one log or many, data frames, the Dask engine.

May import: the base modules, ``core``, ``data``, ``fitting`` and ``evaluation``;
no other top stage (``reporting``, ``fleet``, ``export``, ``sim``).
"""
