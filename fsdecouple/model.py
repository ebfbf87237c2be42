"""The coupling error model of Section 2: three omega slopes and six chi SVRs.

``fit`` establishes the model from a calibration set (Section 2.3, steps 1-4);
``CouplingErrorModel.decouple`` turns measured voltages into forces by eq. (11).
The model file is one JSON document that needs numpy, not libsvm, to evaluate.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import platform
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from . import __version__
from .config import AXES, VOLTAGE_COLUMNS, Settings, settings_from_dict
from .errors import InputError, ModelFileError
from .fast import MAX_SURROGATE_ERROR, FastDecoupler, usable
from .io import atomic_write
from .kernel import rbf_sum
from .linear import fit_omega
from .metrics import interference_errors
from .surrogate import ChiSurrogate, build_pair, table_interval

if TYPE_CHECKING:
    from .calibration import CalibrationSet

FORMAT = "fsdecouple.model"
FORMAT_VERSION = 1

# chi_ab: the coupling error element e_ab on output a caused by a load on b,
# evaluated at the prime voltage u_b (eq. 4).  Order as in eq. (11).
CHI_NAMES = ("xy", "xz", "yx", "yz", "zx", "zy")

# Kernel input span, in kernel widths delta, outside which Table 2's gamma is a
# poor match for the data's units (volts of order 1 give a span of about 3).
KERNEL_SPAN_RANGE = (0.1, 30.0)


@dataclass(frozen=True)
class Chi:
    """A corrected coupling function chi_ab (eq. 4) fitted by epsilon-SVR.

    ``chi(u) = output_scale * (sum_i dual_coef_i exp(-gamma (u/input_scale - sv_i)^2) - rho)``
    """

    name: str
    gamma: float
    support_vectors: np.ndarray
    dual_coef: np.ndarray
    rho: float
    input_scale: float = 1.0
    output_scale: float = 1.0
    input_range: tuple[float, float] = (-np.inf, np.inf)  # prime voltages trained on [V]
    n_points: int = 0
    surrogate: ChiSurrogate | None = None  # fast, verified stand-in (surrogate.py)

    @property
    def output_axis(self) -> int:
        return AXES.index(self.name[0])

    @property
    def input_axis(self) -> int:
        return AXES.index(self.name[1])

    def __call__(self, u: np.ndarray) -> np.ndarray:
        """Coupling error element [V] at prime voltage(s) ``u`` [V], exact kernel sum.

        Always the kernel sum, never the surrogate: this is the reference the
        surrogate is checked against.
        """
        x = np.asarray(u, dtype=float) / self.input_scale
        return self.output_scale * rbf_sum(
            x, self.support_vectors, self.dual_coef, self.gamma, -self.rho
        )

    def to_dict(self) -> dict[str, Any]:
        d = {
            "output_axis": self.name[0],
            "input_axis": self.name[1],
            "kernel": "rbf",
            "gamma": self.gamma,
            "support_vectors": self.support_vectors.tolist(),
            "dual_coef": self.dual_coef.tolist(),
            "rho": self.rho,
            "input_scale": self.input_scale,
            "output_scale": self.output_scale,
            "input_range": list(self.input_range),
            "n_points": self.n_points,
        }
        if self.surrogate is not None:
            d["surrogate"] = self.surrogate.to_dict()
        return d

    @classmethod
    def from_dict(cls, name: str, d: dict[str, Any]) -> Chi:
        sv = np.asarray(d["support_vectors"], dtype=float)
        coef = np.asarray(d["dual_coef"], dtype=float)
        if sv.ndim != 1 or sv.shape != coef.shape:
            raise ValueError("support_vectors and dual_coef differ in length")
        lo, hi = (float(v) for v in d["input_range"])
        surrogate = ChiSurrogate.from_dict(d["surrogate"]) if "surrogate" in d else None
        chi = cls(
            name, float(d["gamma"]), sv, coef, float(d["rho"]), float(d["input_scale"]),
            float(d["output_scale"]), (lo, hi), int(d["n_points"]), surrogate,
        )
        if not (np.isfinite(chi.gamma) and chi.gamma > 0):
            raise ValueError(f"gamma = {chi.gamma!r}, expected a positive number")
        if not (np.isfinite(sv).all() and np.isfinite(coef).all() and np.isfinite(chi.rho)):
            raise ValueError("support vectors, dual coefficients and rho must be finite")
        for scale in (chi.input_scale, chi.output_scale):
            if not (np.isfinite(scale) and scale != 0):
                raise ValueError(f"scale {scale!r}, expected a finite non-zero number")
        return chi


@dataclass
class CouplingErrorModel:
    """A fitted coupling error model (Figure 1): omega slopes and six chi.

    Attributes
    ----------
    settings : Settings
        The settings it was fitted with.
    k : ndarray, shape (3,)
        k_xx, k_yy, k_zz of eq. (2) [V/N].
    chi : dict of str to Chi
        The six corrected coupling functions, keyed ``"xy" ... "zy"``.
    report : dict
        Fit figures: R^2 per axis, support vectors, gamma before/after, warnings.
    provenance : dict
        Input files and digests, library versions.
    created : str
        UTC creation time (ISO 8601).
    """

    settings: Settings
    k: np.ndarray
    chi: dict[str, Chi]
    report: dict[str, Any] = field(default_factory=dict)
    provenance: dict[str, Any] = field(default_factory=dict)
    created: str = ""
    _fast: Any = field(default=None, init=False, repr=False, compare=False)

    @property
    def warnings(self) -> list[str]:
        return list(self.report.get("warnings", []))

    @property
    def calibrated_range(self) -> np.ndarray:
        """Prime-voltage range of the calibration per axis, shape (3, 2) [V]."""
        r = np.empty((3, 2))
        for a, axis in enumerate(AXES):
            ranges = [c.input_range for c in self.chi.values() if c.name[1] == axis]
            r[a] = (min(lo for lo, _ in ranges), max(hi for _, hi in ranges))
        return r

    def coupling_errors(self, u: np.ndarray) -> np.ndarray:
        """Measured coupling errors e_x, e_y, e_z [V] (eq. 1 with eq. 4 at u_(t)).

        e_x = chi_xy(u_y) + chi_xz(u_z), and likewise for y and z.
        """
        u = np.asarray(u, dtype=float).reshape(-1, 3)
        e = np.zeros_like(u)
        for c in self.chi.values():
            e[:, c.output_axis] += c(u[:, c.input_axis])
        return e

    def decouple(
        self, u: np.ndarray, *, rotate: bool = True, exact: bool = False, workers: int | None = None
    ) -> np.ndarray:
        """Forces [N] from zero-corrected voltages [V] by eq. (11).

        f_x(m) = omega_x^-1[u_x - chi_xy(u_y) - chi_xz(u_z)], likewise for y, z;
        then, if the config gives one and ``rotate``, the rotation from the sensor
        frame to the reference frame (end of Section 2.3).

        Parameters
        ----------
        u : array_like, shape (n, 3) or (3,)
            Voltages u_x, u_y, u_z [V], zero-corrected.
        exact : bool
            Evaluate every chi by its kernel sum.  By default the chi surrogates
            stored in the model are used inside their intervals (each within its
            recorded ``max_error`` <= 1e-9 V of the kernel sum) and the kernel sum
            outside them; models without surrogates are always exact.
        workers : int, optional
            Threads for the fast path; default: the number of cores.
        """
        u_arr = np.asarray(u, dtype=float)
        flat = u_arr.reshape(-1, 3)
        fast = None if exact else self.fast_decoupler()
        if fast is not None:
            return fast.decouple(flat, rotate=rotate, workers=workers).reshape(u_arr.shape)
        f = (flat - self.coupling_errors(flat)) / self.k
        if rotate and self.settings.rotation is not None:
            f = f @ np.asarray(self.settings.rotation).T
        return f.reshape(u_arr.shape)

    def fast_decoupler(self):
        """The table evaluator of :mod:`fsdecouple.fast`, or None without surrogates."""
        if self._fast is None:
            self._fast = FastDecoupler.from_model(self) or False
        return self._fast or None

    def decoupler(self):
        """A plain-Python function ``(ux, uy, uz) -> (fx, fy, fz)`` for control loops.

        About a microsecond per call: no numpy, no allocation beyond the result
        tuple.  Same tables and arithmetic as :meth:`decouple` (equal to it within
        1e-12 N); exact kernel sum for inputs outside the tables and for NaN.

        >>> f = model.decoupler()
        >>> fx, fy, fz = f(0.5, 0.01, -0.2)
        """
        fast = self.fast_decoupler()
        if fast is not None:
            return fast.one()

        def exact_one(ux: float, uy: float, uz: float) -> tuple[float, float, float]:
            fx, fy, fz = self.decouple([ux, uy, uz], exact=True).tolist()
            return fx, fy, fz

        return exact_one

    def decouple_one(self, ux: float, uy: float, uz: float) -> tuple[float, float, float]:
        """Forces [N] for one voltage vector [V]; see :meth:`decoupler` for loops."""
        return self.decoupler()(ux, uy, uz)

    def initial_forces(self, u: np.ndarray) -> np.ndarray:
        """Forces with no coupling correction, f = omega^-1(u) per axis (eq. 13 form)."""
        return np.asarray(u, dtype=float).reshape(-1, 3) / self.k

    # --- the model file ---------------------------------------------------------

    def to_dict(self) -> dict[str, Any]:
        doc = {
            "format": FORMAT,
            "format_version": FORMAT_VERSION,
            "fsdecouple_version": __version__,
            "created": self.created,
            "sensor": self.settings.sensor,
            "settings": self.settings.to_dict(),
            "omega": {
                axis: {"k": float(self.k[a]), "inverse": float(1.0 / self.k[a]),
                       "r2": self.report.get("r2", {}).get(axis)}
                for a, axis in enumerate(AXES)
            },
            "chi": {name: c.to_dict() for name, c in self.chi.items()},
            "provenance": self.provenance,
            "report": self.report,
        }
        doc["integrity"] = {"algorithm": "sha256", "digest": content_digest(doc)}
        return doc

    @classmethod
    def from_dict(cls, doc: Any, source: str = "model") -> CouplingErrorModel:
        return model_from_dict(doc, source)

    def save(self, path: str | Path, *, force: bool = True) -> None:
        """Write the model file atomically (sorted keys, no NaN)."""
        text = json.dumps(self.to_dict(), indent=1, sort_keys=True, allow_nan=False)
        with atomic_write(path, force=force) as fh:
            fh.write(text + "\n")

    @classmethod
    def load(cls, path: str | Path) -> CouplingErrorModel:
        return load_model(path)


def content_digest(doc: dict[str, Any]) -> str:
    """SHA-256 of the canonical JSON of everything but ``integrity`` and ``created``.

    Leaving out the creation time makes refits of the same data byte-identical
    in everything but that one field.
    """
    body = {k: v for k, v in doc.items() if k not in ("integrity", "created")}
    canonical = json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(canonical.encode("utf-8")).hexdigest()


def model_from_dict(doc: Any, source: str = "model") -> CouplingErrorModel:
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise ModelFileError(f"{source}: not an fsdecouple model file (format is not '{FORMAT}')")
    version = doc.get("format_version")
    if not isinstance(version, int) or isinstance(version, bool):
        raise ModelFileError(
            f"{source}: format_version is missing or not a whole number ({version!r})"
        )
    if version < 1:
        raise ModelFileError(f"{source}: format_version {version} is unknown (versions start at 1)")
    if version > FORMAT_VERSION:
        raise ModelFileError(
            f"{source}: format_version {version} was written by a newer fsdecouple "
            f"({doc.get('fsdecouple_version', '?')}); this one reads up to {FORMAT_VERSION}"
        )
    integrity = doc.get("integrity")
    digest = integrity.get("digest") if isinstance(integrity, dict) else None
    if not isinstance(digest, str):
        raise ModelFileError(
            f"{source}: has no integrity digest, so it cannot be trusted (written by hand "
            "or by another tool?); refit the model"
        )
    try:
        expected = content_digest(doc)
    except (TypeError, ValueError) as err:  # NaN, inf or non-JSON values in a dict
        raise ModelFileError(f"{source}: malformed model file ({err})") from None
    if digest != expected:
        raise ModelFileError(
            f"{source}: integrity check failed: the content does not match its SHA-256 "
            "digest (edited by hand or corrupted); refit the model"
        )
    try:
        settings = settings_from_dict(_settings_yaml_form(doc["settings"]), f"{source}: settings")
        k = np.array([float(doc["omega"][a]["k"]) for a in AXES])
        chi = {}
        for name in CHI_NAMES:
            if name not in doc["chi"]:
                raise ModelFileError(f"{source}: malformed model file (chi '{name}' is missing)")
            try:
                chi[name] = Chi.from_dict(name, doc["chi"][name])
            except (KeyError, TypeError, ValueError) as err:
                raise ModelFileError(
                    f"{source}: malformed model file (chi '{name}': {err})"
                ) from None
    except (KeyError, TypeError, ValueError) as err:
        raise ModelFileError(f"{source}: malformed model file ({type(err).__name__}: {err})") from None
    bad = [a for a, v in zip(AXES, k, strict=True) if not (np.isfinite(v) and v != 0.0)]
    if bad:
        raise ModelFileError(
            f"{source}: omega {bad[0]}: slope k = {float(k[AXES.index(bad[0])])!r}, expected a finite "
            "non-zero number"
        )
    report = doc.get("report")
    _check_report(report, source)
    return CouplingErrorModel(
        settings, k, chi, report, doc.get("provenance", {}), doc.get("created", "")
    )


def _check_report(report: Any, source: str) -> None:
    """The fit figures ``show`` prints: per-axis numbers and a list of warnings."""
    def number(v):
        return isinstance(v, int | float) and not isinstance(v, bool)

    if not isinstance(report, dict):
        raise ModelFileError(f"{source}: malformed model file (report is not a mapping)")
    for key in ("r2", "n_points", "gamma_before", "gamma_after"):
        table = report.get(key)
        if not (isinstance(table, dict) and all(number(table.get(a)) for a in AXES)):
            raise ModelFileError(
                f"{source}: malformed model file (report: {key} needs a number per axis)"
            )
    warnings = report.get("warnings", [])
    if not (isinstance(warnings, list) and all(isinstance(w, str) for w in warnings)):
        raise ModelFileError(f"{source}: malformed model file (report: warnings is not a list of text)")


def _settings_yaml_form(d: dict[str, Any]) -> dict[str, Any]:
    """Settings.to_dict() output back into the YAML config's shape."""
    d = dict(d)
    svr = dict(d.pop("svr"))
    return {**d, "svr": svr}


class _NonFinite(ValueError):
    pass


class _DuplicateKey(ValueError):
    pass


def _unique_keys(pairs):
    # the digest covers the parsed document, so a second, shadowed key would
    # pass it while showing a reader a value the model does not use
    doc = dict(pairs)
    if len(doc) != len(pairs):
        seen = set()
        raise _DuplicateKey(next(k for k, _ in pairs if k in seen or seen.add(k)))
    return doc


def _finite_float(text: str) -> float:
    value = float(text)
    if not np.isfinite(value):  # 1e999 parses to inf
        raise _NonFinite(text)
    return value


def _refuse_constant(name: str):
    # json accepts NaN/Infinity, which the writer never produces (allow_nan=False)
    raise _NonFinite(name)


def load_model(path: str | Path) -> CouplingErrorModel:
    """Read and verify a model file."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")  # a BOM from a Windows editor is not content
    except FileNotFoundError:
        raise ModelFileError(f"{path}: model file not found") from None
    except (OSError, UnicodeDecodeError) as err:
        raise ModelFileError(f"{path}: cannot read model file ({err})") from None
    try:
        doc = json.loads(
            text, parse_constant=_refuse_constant, parse_float=_finite_float,
            object_pairs_hook=_unique_keys,
        )
    except json.JSONDecodeError as err:
        raise ModelFileError(
            f"{path}, row {err.lineno}, column {err.colno}: not valid JSON (truncated?)"
        ) from None
    except _DuplicateKey as err:
        raise ModelFileError(
            f"{path}: key '{err.args[0]}' appears twice in one object (edited by hand?); "
            "json would keep the last one silently"
        ) from None
    except _NonFinite as err:
        raise ModelFileError(
            f"{path}: holds {err.args[0]!r}; NaN and infinity are not allowed in a model file"
        ) from None
    except RecursionError:
        raise ModelFileError(f"{path}: not a model file (JSON too deeply nested)") from None
    except ValueError as err:  # e.g. an integer of more than 4300 digits
        raise ModelFileError(f"{path}: not a model file ({err})") from None
    return model_from_dict(doc, str(path))


# --- fitting ---------------------------------------------------------------------


def _library_versions() -> dict[str, str]:
    return dict(_installed_versions())  # a copy: each model owns its provenance


@functools.cache
def _installed_versions() -> dict[str, str]:
    # reading package metadata costs ~5 ms; cv fits dozens of models
    out = {"python": platform.python_version()}
    for dist in ("numpy", "scipy", "pandas", "libsvm-official"):
        try:
            out[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            out[dist] = "not installed"
    return out


def chi_training_data(calib: CalibrationSet, name: str) -> tuple[np.ndarray, np.ndarray]:
    """(prime voltage, coupling error element) of chi_ab from the b sweeps, file order.

    Section 2.1: in the b-direction calibration data u_b = u_bb and u_a = e_ab.
    """
    s = calib.sweep(name[1])
    return (
        s[VOLTAGE_COLUMNS[AXES.index(name[1])]].to_numpy(dtype=float),
        s[VOLTAGE_COLUMNS[AXES.index(name[0])]].to_numpy(dtype=float),
    )


def fit(
    calib: CalibrationSet | str | Path,
    settings: Settings | None = None,
    *,
    workers: int | None = None,
) -> CouplingErrorModel:
    """Establish the coupling error model (Section 2.3, steps 1-4).

    Parameters
    ----------
    calib : CalibrationSet or path
        Zero-corrected calibration set, or a path to read one from.
    settings : Settings, optional
        Defaults to the paper's sensor and Table 2.
    workers : int, optional
        Threads training the six SVRs (libsvm releases the GIL); default: the
        number of cores.  The result does not depend on it.
    """
    # fitting needs pandas (calibration) and libsvm; loading and applying a model do not
    from .calibration import CalibrationSet, load_calibration
    from .svr import fit_svr  # the only libsvm user

    settings = settings or Settings()
    if not isinstance(calib, CalibrationSet):
        calib = load_calibration(calib, settings)
    omega = fit_omega(calib.points)
    warnings = list(calib.warnings)
    for a, axis in enumerate(AXES):
        if not np.isfinite(omega.k[a]) or omega.k[a] == 0.0:
            raise InputError(
                f"{calib.source}: the {axis} sweeps' prime voltage u{axis} does not change with f{axis}; "
                f"cannot fit omega_{axis} (eq. 2)"
            )
        if not omega.r2[a] >= settings.min_r2:
            warnings.append(
                f"omega_{axis}: R^2 = {omega.r2[a]:.5f} is below {settings.min_r2} "
                "(assumption 1 of Section 2.1: prime force and voltage are linear)"
            )
    # Kernel scaling: "full_scale" divides inputs and targets by each axis's
    # full-scale output |k| F_FS [V], so Table 2's gamma suits mV or ADC counts too.
    if settings.scaling == "full_scale":
        scale = np.abs(omega.k) * np.asarray(settings.full_scale)
    else:
        scale = np.ones(3)
    jobs = []
    for name in CHI_NAMES:
        x, y = chi_training_data(calib, name)
        o, i = AXES.index(name[0]), AXES.index(name[1])
        jobs.append((name, x, y, float(scale[i]), float(scale[o])))
    for a, axis in enumerate(AXES):
        x = calib.sweep(axis)[VOLTAGE_COLUMNS[a]].to_numpy() / scale[a]
        span = (x.max() - x.min()) * np.sqrt(2.0 * settings.svr.gamma)
        lo, hi = KERNEL_SPAN_RANGE
        if not lo <= span <= hi:
            warnings.append(
                f"chi inputs from u{axis} span {span:.3g} kernel widths (expected "
                f"{lo:g} to {hi:g} for delta^2 = {settings.svr.delta2:g}); the voltages may "
                "be in mV or ADC counts: set 'scaling: full_scale' in the config"
            )

    def one(job):
        name, x, y, in_scale, out_scale = job
        s = fit_svr(x / in_scale, y / out_scale, settings.svr)
        return Chi(
            name, s.gamma, s.support_vectors, s.dual_coef, s.rho, in_scale, out_scale,
            (float(x.min()), float(x.max())), int(x.size),
        )

    def tables(axis: str) -> list[Chi]:
        # both chi fed by one input axis share one grid (one index per voltage)
        pair = [c for c in chis if c.name[1] == axis]
        lo, hi = table_interval(min(c.input_range[0] for c in pair),
                                max(c.input_range[1] for c in pair))
        return [replace(c, surrogate=s) for c, s in zip(pair, build_pair(pair, lo, hi), strict=True)]

    n_workers = workers or min(len(jobs), os.cpu_count() or 1)
    if n_workers > 1:
        with ThreadPoolExecutor(n_workers) as pool:
            chis = list(pool.map(one, jobs))
            done = [c for pair in pool.map(tables, AXES) for c in pair]
    else:
        chis = [one(j) for j in jobs]
        done = [c for axis in AXES for c in tables(axis)]
    by_name = {c.name: c for c in done}
    for c in done:
        if not usable(c.surrogate):
            warnings.append(
                f"chi_{c.name}: its surrogate table reaches only {c.surrogate.max_error:.2g} V of "
                f"the kernel sum (needs <= {MAX_SURROGATE_ERROR:g} V); this model decouples by the "
                "exact kernel sum, about 100x slower"
            )
    model = CouplingErrorModel(settings, omega.k, {name: by_name[name] for name in CHI_NAMES})
    u = calib.voltages
    before = interference_errors(calib.points, model.initial_forces(u), settings.full_scale)
    after = interference_errors(calib.points, model.decouple(u, rotate=False, exact=True),
                                settings.full_scale)
    model.report = {
        "r2": dict(zip(AXES, map(float, omega.r2), strict=True)),
        "n_points": dict(zip(AXES, map(int, omega.n), strict=True)),
        "n_support_vectors": {c.name: int(c.support_vectors.size) for c in chis},
        "surrogate_max_error": {n: c.surrogate.max_error for n, c in model.chi.items()},
        "gamma_before": before,
        "gamma_after": after,
        "repetitions": calib.repetitions,
        "warnings": warnings,
    }
    model.provenance = {
        "files": [{"path": p, "sha256": h} for p, h in calib.files],
        "libraries": _library_versions(),
    }
    model.created = datetime.now(UTC).replace(microsecond=0).isoformat()
    return model
