"""Many sensors: ``fit-many`` over a directory of sensors, ``compare`` and drift.

May import: the base modules, ``core``, ``data``, ``fitting`` and ``evaluation``;
no other top stage (``reporting``, ``logs``, ``export``, ``sim``).
The old module ``fsdecouple.fleet``'s names (``fit_many``, ...) still import from here.
"""


def __getattr__(name: str):
    import importlib

    try:
        return getattr(importlib.import_module(f"{__name__}.sensors"), name)
    except AttributeError:
        raise AttributeError(f"module 'fsdecouple.fleet' has no attribute {name!r}") from None
