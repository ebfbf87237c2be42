"""The C header: a model as one dependency-free C99 file for controllers.

``plan`` holds what the header holds (the model's decoupling plan with the header's
tables), ``header`` decides and checks every number of it (``export_header``),
``tables`` builds coarser chi tables to an error bound, ``c_source`` writes the C
text and ``c_function`` the decoupling function, the plan's steps in order.

May import: the base modules, ``core``, ``data``, ``fitting`` and ``evaluation``;
no other top stage (``reporting``, ``logs``, ``fleet``, ``sim``).
The old module ``fsdecouple.export``'s names (``export_header``, ``plan_export``, ...)
still import from here.
"""


__all__ = ["ExportPlan", "ExportResult", "PRECISIONS", "emulate_float", "exact_forces",
           "expected_status", "export_header", "float_bound", "plan_export"]  # noqa: F822 (lazy)


def __getattr__(name: str):
    import importlib

    try:
        return getattr(importlib.import_module(f"{__name__}.header"), name)
    except AttributeError:
        raise AttributeError(f"module 'fsdecouple.export' has no attribute {name!r}") from None
