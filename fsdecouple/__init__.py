"""fsdecouple: static decoupling of multi-axis force sensors.

The method is the coupling error model with epsilon-SVRs of Ma et al.,
"A Robust Static Decoupling Algorithm for 3-Axis Force Sensors Based on Coupling
Error Model and epsilon-SVR" (Sensors, 2012).  Every command of the CLI is a
plain Python call here:

>>> import fsdecouple
>>> calib = fsdecouple.load_calibration("sample_data/calibration", fsdecouple.load_config())
>>> model = fsdecouple.fit(calib)
>>> fsdecouple.save_model(model, "model.json")
>>> forces = fsdecouple.load_model("model.json").decouple([[0.5, 0.01, -0.2]])
"""

__version__ = "0.1.0"

# The public names load on first use (PEP 562): ``fsdecouple apply`` and a
# control loop that loads a model need numpy and pyarrow, not pandas or libsvm.
_PUBLIC = {
    "CalibrationSet": "data.calibration",
    "load_calibration": "data.calibration",
    "ingest_summary": "data.calibration",
    "Settings": "config",
    "load_config": "config",
    "FsdecoupleError": "errors",
    "CouplingErrorModel": "core.model",
    "FitReport": "core.model",
    "load_model": "core.modelfile",
    "save_model": "core.modelfile",
    "apply_file": "logs.apply",
    "decouple_frame": "logs.frame",
    "run_cv": "evaluation.cv",
    "load_cv_results": "evaluation.cv_results",
    "build_report": "reporting.report",
    "validate": "evaluation.validate",
    "import_cal": "data.ati_model",
    "export_cal": "export.ati_cal",
    "fit": "evaluation.calibrate",
    "frame_tare": "logs.frame",
    "frame_forces": "logs.frame",
    "apply_many": "logs.many",
    "parse_folds": "evaluation.heldout",
    "export_header": "export.header",
    "compare": "fleet.drift",
    "fit_many": "fleet.sensors",
    "certificate": "evaluation.certificate_doc",
    "write_certificate": "reporting.certificate_file",
    "init_config": "data.init_config",
}
__all__ = sorted(_PUBLIC)  # noqa: F822


def __getattr__(name: str):
    if name not in _PUBLIC:
        raise AttributeError(f"module 'fsdecouple' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(f".{_PUBLIC[name]}", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted([*globals(), *_PUBLIC])
