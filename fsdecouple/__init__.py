"""fsdecouple: static decoupling of 3-axis force sensors.

The method is the coupling error model with six epsilon-SVRs of Ma et al.,
"A Robust Static Decoupling Algorithm for 3-Axis Force Sensors Based on Coupling
Error Model and epsilon-SVR" (Sensors, 2012).

>>> import fsdecouple
>>> calib = fsdecouple.load_calibration("sample_data/calibration", fsdecouple.load_config())
>>> model = fsdecouple.fit(calib)
>>> forces = model.decouple([[0.5, 0.01, -0.2]])
"""

__version__ = "0.1.0"

from .calibration import CalibrationSet, load_calibration  # noqa: E402
from .config import Settings, load_config  # noqa: E402
from .errors import FsdecoupleError  # noqa: E402
from .model import CouplingErrorModel, fit, load_model  # noqa: E402

__all__ = [
    "CalibrationSet",
    "CouplingErrorModel",
    "FsdecoupleError",
    "Settings",
    "fit",
    "load_calibration",
    "load_config",
    "load_model",
]
