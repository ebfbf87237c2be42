"""Settings: the sensor, the file layout and the epsilon-SVR parameters.

A YAML file (``configs/paper-sensor.yaml`` describes the paper's sensor) is read
with ``yaml.safe_load`` into a frozen :class:`Settings`; command-line flags
override it.  The built-in defaults *are* the paper's sensor (Section 3) and
Table 2, but for libsvm's stopping tolerance: unless one is written, fit solves to
the calibration's noise (fitting/noise.py); a config stating Table 2's 0.001
(``configs/paper-sensor.yaml``) reproduces the paper's set-up exactly.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

from .axes import CANONICAL_COLUMNS, DEFAULT, FORCE_COLUMNS, VOLTAGE_COLUMNS, Layout
from .errors import ConfigError, printable
from .labinfo import LabInfo
from .schema import (
    DEFAULT_EXTRAPOLATION,
    SCALINGS,
    SVR_KEYS,
    check_extrapolation,
    check_refine,
    svr_settings,
    validate,
)
from .temperature_units import config_keys as temperature_keys
from .units import Units
from .wrench import Frame
from .yamlfile import read_yaml

TABLE2_TOLERANCE = 1e-3  # Table 2's libsvm stopping tolerance (-e)


@dataclass(frozen=True)
class SVRSettings:
    """epsilon-SVR parameters of Table 2 (libsvm ``-s 3 -t 2``).

    ``gamma`` is libsvm's kernel parameter, ``exp(-gamma |u - v|^2)``; the paper's
    Gaussian ``exp(-|u - v|^2 / 2 delta^2)`` with delta^2 = 1 gives gamma = 0.5.
    """

    C: float = 1000.0
    epsilon: float = 0.0001
    gamma: float = 0.5
    # libsvm's stopping tolerance: a value written (config or --tolerance) is obeyed
    # exactly; None lets fit set it against the calibration's noise (fitting/noise.py),
    # at most Table 2's TABLE2_TOLERANCE, and the fitted model records the value used
    tolerance: float | None = None

    @property
    def delta2(self) -> float:
        return 1.0 / (2.0 * self.gamma)

    @property
    def table2(self) -> bool:
        """C, epsilon and gamma as Table 2 gives them (the defaults), whatever the tolerance."""
        return (self.C, self.epsilon, self.gamma) == (SVRSettings.C, SVRSettings.epsilon,
                                                      SVRSettings.gamma)

    @property
    def stopping_tolerance(self) -> float:
        """The tolerance libsvm is given: the one written, else Table 2's."""
        return TABLE2_TOLERANCE if self.tolerance is None else self.tolerance

    def libsvm_options(self) -> str:
        return (
            f"-s 3 -t 2 -g {self.gamma!r} -c {self.C!r} -p {self.epsilon!r} "
            f"-e {self.stopping_tolerance!r} -q"
        )


@dataclass(frozen=True)
class Settings:
    """Everything given (not learned) for fitting and applying a model."""

    sensor: str = "paper-3axis"
    full_scale: tuple[float, ...] = (100.0, 100.0, 150.0)  # [N], Section 3; per component
    min_repetitions: int = 6
    columns: dict[str, str] = field(default_factory=lambda: {c: c for c in CANONICAL_COLUMNS})
    scale: dict[str, float] = field(
        default_factory=lambda: {c: 1.0 for c in (*FORCE_COLUMNS, *VOLTAGE_COLUMNS)}
    )
    sep: str = ","
    decimal: str = "."
    # raw output range of each channel (ADC or amplifier), before zero correction
    limits: dict[str, tuple[float, float]] = field(default_factory=dict)
    svr: SVRSettings = SVRSettings()
    scaling: str = "none"
    rotation: tuple[tuple[float, float, float], ...] | None = None
    min_r2: float = 0.99
    refine: int = 0  # fixed-point steps on the prime outputs before eq. (11) (decouple.py)
    extrapolation: str = DEFAULT_EXTRAPOLATION  # model files without it: kernel
    units: Units = Units()
    # the sensor's components and their prime outputs (axes.Layout); None: x, y, z
    components: tuple[str, ...] | None = None
    outputs: tuple[str, ...] | None = None
    zero: str | None = None  # ZERO_MODES; None: rows for x, y, z, fit for components
    # what fit's model decouples by (FIT_METHODS: svr, linear, auto); None: svr, the paper's
    method: str | None = None
    frame: Frame | None = None  # six axes: the wrench transform after eq. (11) (wrench.py)
    lab: LabInfo = LabInfo()  # the certificate's serial, reference, environment (labinfo.py)
    # the top-level keys a config file wrote (schema.py), so a command can tell a value
    # written from a default: not part of the settings themselves
    given: frozenset[str] = field(default=frozenset(), compare=False, repr=False)

    @property
    def zero_method(self) -> str:
        return self.zero or ("rows" if self.components is None else "fit")

    @property
    def layout(self) -> Layout:
        if self.components is None:
            return DEFAULT
        return Layout.named(self.components, self.outputs)

    @property
    def load_unit(self) -> str:
        return self.units.load

    @property
    def output_unit(self) -> str:
        return self.units.output

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        del d["given"]
        if not self.limits:
            del d["limits"]  # files from before limits keep their bytes
        layout = self.layout
        d["full_scale"] = dict(zip(layout.labels, self.full_scale, strict=True))
        if self.zero is None:
            del d["zero"]
        if self.method is None:
            del d["method"]
        if self.frame is None:
            del d["frame"]
        else:
            d["frame"] = self.frame.to_dict()
        if self.components is None:
            del d["components"], d["outputs"]  # files from before components keep their bytes
        else:
            d["components"], d["outputs"] = list(self.components), list(self.outputs)
        d["rotation"] = None if self.rotation is None else [list(r) for r in self.rotation]
        d["csv"] = {"sep": d.pop("sep"), "decimal": d.pop("decimal")}
        d.pop("lab")
        d.update(self.lab.to_dict())  # none of its keys when all are defaults
        d["checks"] = {"min_r2": d.pop("min_r2")}
        if self.refine == 0:
            del d["refine"]  # eq. (11) as written: files from before refine keep their bytes
        if self.units == Units():
            del d["units"]  # the paper's N and V: files from before units keep their bytes
        else:
            d["units"] = self.units.to_dict(layout.loads, layout.outputs)
        return d


FULL_SCALE_RANGE = (1e-12, 1e12)


@temperature_keys  # columns: {temperature: ...}, units: {temperature: ...} (temperature_units.py)
def settings_from_dict(raw: Any, source: str = "config") -> Settings:
    """Validate a parsed YAML document into :class:`Settings` (the keys: schema.py)."""
    settings, given = validate(raw, source, Settings())
    return replace(settings, given=given)


def load_config(path: str | Path | None = None, **overrides: Any) -> Settings:
    """Read a YAML config (``None``: the built-in paper sensor) and apply overrides.

    Overrides are flag values; ``None`` means "not given".  SVR keys (``C``,
    ``epsilon``, ``gamma``, ``delta2``, ``tolerance``) go to :class:`SVRSettings`.
    """
    if path is None:
        settings = Settings()
    else:
        path = Path(path)
        name = printable(path)
        raw = read_yaml(path, name)
        settings = settings_from_dict(raw, name)
    settings = apply_overrides(settings, **overrides)
    for axis, value in zip(settings.layout.labels, settings.full_scale, strict=True):
        low, high = FULL_SCALE_RANGE
        if not low <= value <= high:
            raise ConfigError(f"{name if path is not None else 'config'}: full_scale: {axis}: "
                              f"{value!r} is outside {low:g} .. {high:g}")
    return settings


def apply_overrides(settings: Settings, **overrides: Any) -> Settings:
    given = {k: v for k, v in overrides.items() if v is not None}
    svr_raw = {k: given.pop(k) for k in list(given) if k in SVR_KEYS}
    if svr_raw:
        settings = replace(settings, svr=svr_settings(svr_raw, "command-line SVR setting", settings.svr))
    if "scaling" in given and given["scaling"] not in SCALINGS:
        raise ConfigError(f"--scaling: expected one of {', '.join(SCALINGS)}, found {given['scaling']!r}")
    if "refine" in given:
        given["refine"] = check_refine(given["refine"], "--refine")
    if "extrapolation" in given:
        given["extrapolation"] = check_extrapolation(given["extrapolation"], "--extrapolation")
    return replace(settings, **given)
