"""Old module paths stay importable: ``fsdecouple.fit`` is ``fsdecouple.fitting.fit``.

The modules moved into the stage subpackages (``core``, ``data``, ``fitting``, ...);
code written against the flat layout keeps working through a finder on
``sys.meta_path`` that answers an old name with the module itself (one object, so
patching either name patches both).  ``fsdecouple.export`` and ``fsdecouple.fleet``
are now packages that re-export the old modules' public names.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import types

MOVED = {
    "apply": "logs.apply",
    "baselines": "fitting.baselines",
    "batch": "logs.many",
    "batch_dask": "logs.dask_engine",
    "batch_jobs": "logs.jobs",
    "calibration": "data.calibration",
    "checks": "evaluation.checks",
    "console": "reporting.tables",
    "console_fleet": "reporting.fleet_tables",
    "console_tune": "reporting.tune_table",
    "cv": "evaluation.cv",
    "cv_doc": "evaluation.cv_results",
    "decouple": "core.decouple",
    "drift": "fleet.drift",
    "export_c": "export.c_source",
    "export_tables": "export.tables",
    "extrapolation": "core.extrapolation",
    "fit": "fitting.fit",
    "frame": "logs.frame",
    "guess": "data.columns",
    "guess_layout": "data.init_config",
    "heldout": "evaluation.heldout",
    "htmlparts": "reporting.html",
    "iotools.calibration": "data.calibration_csv",
    "iotools.files": "files",
    "iotools.logs": "logs.reader",
    "iotools.sinks": "logs.sinks",
    "iotools.text": "data.csv_text",
    "kernel": "core.kernel",
    "linear": "fitting.linear",
    "metrics": "core.metrics",
    "model": "core.model",
    "modelfile": "core.modelfile",
    "noise": "fitting.noise",
    "outliers": "fitting.outliers",
    "parallel": "fitting.threads",
    "plots": "reporting.plots",
    "rbf": "fitting.rbf",
    "report": "reporting.report",
    "simulate": "sim.simulate",
    "simulate_lab": "sim.lab",
    "simulate_six": "sim.six_axis",
    "surrogate": "core.surrogate",
    "svr": "fitting.svr",
    "table_kernel": "core.table_kernel",
    "tune": "evaluation.tune",
    "validate": "evaluation.validate",
    "verdict": "evaluation.verdict",
    "zero": "data.zero",
}
_FUNCTIONS = ("fit", "validate")  # public functions named like their old modules


class _OldPaths(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    def find_spec(self, fullname, path=None, target=None):
        old = fullname.partition(".")[2]
        if not fullname.startswith("fsdecouple."):
            return None
        if old == "iotools":  # the old folder: an empty package over its moved modules
            return importlib.util.spec_from_loader(fullname, self, is_package=True)
        if old in MOVED:
            return importlib.util.spec_from_loader(fullname, self)
        return None

    def create_module(self, spec):
        return None

    def exec_module(self, module):
        if module.__name__ == "fsdecouple.iotools":
            return
        # the import system returns what sys.modules holds under the name afterwards
        new = "fsdecouple." + MOVED[module.__name__.partition(".")[2]]
        sys.modules[module.__name__] = importlib.import_module(new)


class _Package(types.ModuleType):
    """``fsdecouple`` itself: importing ``fsdecouple.fit`` binds no module over ``fit()``."""

    def __setattr__(self, name, value):
        if name in _FUNCTIONS and isinstance(value, types.ModuleType):
            return
        super().__setattr__(name, value)


def install() -> None:
    if not any(isinstance(f, _OldPaths) for f in sys.meta_path):
        sys.meta_path.append(_OldPaths())
    sys.modules["fsdecouple"].__class__ = _Package


install()
