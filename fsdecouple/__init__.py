"""fsdecouple: static decoupling of 3-axis force sensors.

The method is the coupling error model with six epsilon-SVRs of Ma et al.,
"A Robust Static Decoupling Algorithm for 3-Axis Force Sensors Based on Coupling
Error Model and epsilon-SVR" (Sensors, 2012).

>>> import fsdecouple
>>> calib = fsdecouple.load_calibration("sample_data/calibration", fsdecouple.load_config())
>>> model = fsdecouple.fit(calib)
>>> forces = model.decouple([[0.5, 0.01, -0.2]])
"""

import os as _os

# Every matrix here is small (hundreds of rows) and fsdecouple parallelises over
# whole jobs (the six SVRs of a fit, the models of cv) with its own threads.
# OpenBLAS's and libsvm's OpenMP worker threads would only compete with those
# threads for the cores, and their spin-waiting made cv up to 10x slower on a
# loaded 2-core machine.  Set before numpy and libsvm load; a value the user
# set wins.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"):
    _os.environ.setdefault(_var, "1")

__version__ = "0.1.0"

# The public names load on first use (PEP 562): ``fsdecouple apply`` and a
# control loop that loads a model need numpy and pyarrow, not pandas or libsvm.
_PUBLIC = {
    "CalibrationSet": "calibration",
    "load_calibration": "calibration",
    "Settings": "config",
    "load_config": "config",
    "FsdecoupleError": "errors",
    "CouplingErrorModel": "model",
    "fit": "model",
    "load_model": "model",
}
__all__ = sorted(_PUBLIC)


def __getattr__(name: str):
    if name not in _PUBLIC:
        raise AttributeError(f"module 'fsdecouple' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(f".{_PUBLIC[name]}", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted([*globals(), *_PUBLIC])
