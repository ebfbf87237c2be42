"""Many sensors: ``fit-many`` over a directory of sensors, ``compare`` and drift.

May import: the base modules, ``core``, ``data``, ``fitting`` and ``evaluation``;
no other top stage (``reporting``, ``logs``, ``export``, ``sim``).
The old module ``fsdecouple.fleet``'s names (``fit_many``, ...) still import from here.
"""


__all__ = ["FleetResult", "SensorResult", "calibration_path", "fit_many", "fit_sensor",  # noqa: F822
           "sensor_dirs"]  # the old module's names, loaded on first use


def __getattr__(name: str):
    import importlib

    try:
        return getattr(importlib.import_module(f"{__name__}.sensors"), name)
    except AttributeError:
        raise AttributeError(f"module 'fsdecouple.fleet' has no attribute {name!r}") from None
