"""The coupling error model of Section 2: N omega slopes and N(N - 1) chi SVRs.

A fitted :class:`CouplingErrorModel` turns zero-corrected outputs into forces by
eq. (11) (:mod:`fsdecouple.core.decouple`).  It is established by
:func:`fsdecouple.fitting.fit.fit` and stored by :mod:`fsdecouple.core.modelfile`; evaluating
it needs numpy only.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from functools import cached_property
from typing import Any

import numpy as np

from ..axes import Layout, NamedChi, chi_labels
from ..config import Settings
from ..errors import ConfigError
from ..schema import check_refine, refine_argument
from .decouple import coupling_errors as _coupling_errors
from .decouple import exact as _exact_plan
from .decouple import initial_forces
from .extrapolation import Edges, continue_slopes, continue_values, edges
from .kernel import rbf_sum, rbf_sum_slope
from .plan import Plan, model_plan, temperature_inputs, temperature_step, zero_step
from .surrogate import ChiSurrogate
from .table_path import TableDecoupler
from .temperature import TemperatureTerms


@dataclass(frozen=True)
class Chi(NamedChi):
    """A corrected coupling function chi_ab (eq. 4) fitted by epsilon-SVR.

    ``chi(u) = output_scale * (sum_i dual_coef_i exp(-gamma (u/input_scale - sv_i)^2) - rho)``

    inside ``input_range``; beyond it, with ``extrapolation = "tangent"``, the
    tangent at the nearer edge (:mod:`fsdecouple.core.extrapolation`).  The model sets
    ``extrapolation`` from its settings; it is not part of the chi's own record.
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
    extrapolation: str = "kernel"  # beyond input_range: "kernel" sum or "tangent"
    pair: tuple[int, int] | None = None  # (output a, input b); None: read from an "xy" name

    def kernel(self, u: np.ndarray) -> np.ndarray:
        """The kernel sum [V] at prime voltage(s) ``u`` [V] (eq. 10), also beyond the range."""
        x = np.asarray(u, dtype=float) / self.input_scale
        return self.output_scale * rbf_sum(
            x, self.support_vectors, self.dual_coef, self.gamma, -self.rho
        )

    def kernel_slope(self, u: np.ndarray) -> np.ndarray:
        """d/du of :meth:`kernel` [V/V], analytically."""
        x = np.asarray(u, dtype=float) / self.input_scale
        return rbf_sum_slope(x, self.support_vectors, self.dual_coef, self.gamma) * (
            self.output_scale / self.input_scale)

    @cached_property
    def edges(self) -> Edges | None:
        """The tangents at the ends of ``input_range``; None for ``kernel`` extrapolation."""
        if self.extrapolation != "tangent":
            return None
        return edges(*self.input_range, self.kernel, self.kernel_slope)

    def __call__(self, u: np.ndarray) -> np.ndarray:
        """Coupling error element [V] at prime voltage(s) ``u`` [V], exact.

        The kernel sum (continued by its tangents beyond ``input_range`` under
        ``tangent`` extrapolation), never the surrogate: this is the reference
        the surrogate is checked against.
        """
        out = self.kernel(u)
        e = self.edges
        return out if e is None else continue_values(u, out, e)

    def slope(self, u: np.ndarray) -> np.ndarray:
        """d chi / du [V/V] of :meth:`__call__` (the surrogate tables' knot slopes)."""
        out = self.kernel_slope(u)
        e = self.edges
        return out if e is None else continue_slopes(u, out, e)

    def to_dict(self) -> dict[str, Any]:
        out, inp = chi_labels(self.name)
        d = {
            "output_axis": out,
            "input_axis": inp,
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
    def from_dict(cls, name: str, d: dict[str, Any], pair: tuple[int, int] | None = None) -> Chi:
        sv = np.asarray(d["support_vectors"], dtype=float)
        coef = np.asarray(d["dual_coef"], dtype=float)
        if sv.ndim != 1 or sv.shape != coef.shape:
            raise ValueError("support_vectors and dual_coef differ in length")
        lo, hi = (float(v) for v in d["input_range"])
        surrogate = ChiSurrogate.from_dict(d["surrogate"]) if "surrogate" in d else None
        chi = cls(
            name, float(d["gamma"]), sv, coef, float(d["rho"]), float(d["input_scale"]),
            float(d["output_scale"]), (lo, hi), int(d["n_points"]), surrogate, pair=pair,
        )
        if not (np.isfinite(chi.gamma) and chi.gamma > 0):
            raise ValueError(f"gamma = {chi.gamma!r}, expected a positive number")
        if not (np.isfinite(sv).all() and np.isfinite(coef).all() and np.isfinite(chi.rho)):
            raise ValueError("support vectors, dual coefficients and rho must be finite")
        for key in ("input_scale", "output_scale"):
            scale = getattr(chi, key)
            if not (np.isfinite(scale) and scale > 0):  # fit writes positive scales only
                raise ValueError(f"{key} {scale!r}, expected a finite positive number")
        if not lo <= hi:
            raise ValueError(f"input_range [{lo!r}, {hi!r}] is inverted, expected lo <= hi")
        return chi


RANGE_MARGIN = 0.01  # of the calibrated span: see CouplingErrorModel.extrapolation_limits
# A force beyond this many times the largest full-scale load is no measurement (a
# voltage of 1e300, a slope of 1e300 in a model file): apply gives it the status
# not_finite, as it does an overflow, and the C export its NOT_FINITE bit.
FORCE_LIMIT = 1e6
# a linear model decouples by its matrix: no chi for refinement's steps (eqs. 5-6)
LINEAR_NOT_REFINED = ("a linear model decouples by its calibration matrix, which has no "
                      "coupling functions to refine (eqs. 5-6): leave refine at 0")


@dataclass
class FitReport:
    """What the fit measured, as ``fit`` prints it and the model file stores it.

    Per-axis mappings are keyed by axis name; fractions are of full scale.
    """

    r2: dict[str, float]
    n_points: dict[str, int]
    gamma_before: dict[str, float]  # eq. (12), initial forces omega^-1(u)
    gamma_after: dict[str, float]  # eq. (12), decoupled by eq. (11)
    n_support_vectors: dict[str, int] = field(default_factory=dict)
    surrogate_max_error: dict[str, float] | None = None
    repetitions: list[int] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    verdict: dict[str, Any] | None = None  # held-out comparison (fsdecouple.evaluation.verdict)
    outliers: list[dict[str, Any]] | None = None  # possible gross errors (fsdecouple.fitting.outliers)
    tune: dict[str, Any] | None = None  # fit --tune's grid and choice (evaluation.tune); None: untuned
    # per step: outputs, model error and U; held-out scores for intervals (evaluation.budget)
    certificate: dict[str, Any] | None = None
    # the temperature terms' fit: b, g with uncertainties, the held-out figure (fitting/temperature.py)
    temperature: dict[str, Any] | None = None

    def to_dict(self) -> dict[str, Any]:
        d = {f.name: getattr(self, f.name) for f in fields(self)}
        for key in ("surrogate_max_error", "verdict", "outliers", "tune", "certificate",
                    "temperature"):
            if d[key] is None:  # files from before these figures
                del d[key]
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> FitReport:
        known = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in d.items() if k in known})


@dataclass
class CouplingErrorModel:
    """A fitted coupling error model (Figure 1): omega slopes and N(N - 1) chi.

    Attributes
    ----------
    settings : Settings
        The settings it was fitted with.
    k : ndarray, shape (N,)
        k_aa of eq. (2) [V/N].
    chi : dict of str to Chi
        The corrected coupling functions, keyed ``"xy" ... "zy"`` (eq. 11 order).
    report : FitReport
        Fit figures: R^2 per axis, support vectors, gamma before/after, warnings.
    method : str
        What :meth:`decouple` uses: ``svr``, eq. (11) with the chi (the paper's
        method), or ``linear``, the least-squares calibration matrix ``f = C u``
        (``fit --method linear|auto``; omega and chi are kept as the diagnostics of
        the sensor's coupling).
    matrix : ndarray, shape (N, N), optional
        The least-squares calibration matrix C [load unit / output unit] of the same
        calibration: how a ``linear`` model decouples; an ``svr`` model fitted by
        ``fit`` keeps it for comparison (``validate``), never to decouple.
    own : dict of str to Chi
        Own-load chi_aa(u_a), keyed ``"fx:fx"``: the nonlinearity of each output in its
        own load, which a joint fit of rig rows adds (:mod:`fsdecouple.fitting.joint`);
        empty for the paper's model.  Tabled on their input's grid like the cross chi.
    projection : ndarray, shape (N, M), optional
        M > N outputs (fitting/gauges.py): P = K^+ of the linear forward model; eq. (11)
        then acts on v = P u, in load units with k = 1.  None: one output per component.
    temperature : TemperatureTerms, optional
        Per-output offset and gain drift about T0 (:mod:`fsdecouple.core.temperature`),
        corrected before eq. (11) by :meth:`zero_corrected`; one output is the temperature.
    zero : ndarray, shape (M,), optional
        Each output's offset fitted with the loads (``zero: intercept``, data/zero.py) [output
        unit]: the zero ``apply`` subtracts from a log's raw outputs when given neither
        ``--tare`` nor ``--zero``.  None: the outputs are zeroed by a tare, as Section 3's.
    provenance : dict
        Input files and digests, library versions.
    created : str
        UTC creation time (ISO 8601).
    """

    settings: Settings
    k: np.ndarray
    chi: dict[str, Chi]
    report: FitReport | None = None
    provenance: dict[str, Any] = field(default_factory=dict)
    created: str = ""
    method: str = "svr"
    matrix: np.ndarray | None = None
    own: dict[str, Chi] = field(default_factory=dict)
    projection: np.ndarray | None = None
    temperature: TemperatureTerms | None = None
    zero: np.ndarray | None = None  # zero: intercept's fitted offsets [output unit]
    _tables: Any = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        # each chi evaluates itself: it takes the model's extrapolation mode
        mode = getattr(self.settings, "extrapolation", "kernel")
        self.chi, self.own = ({name: c if getattr(c, "extrapolation", mode) == mode
                               else replace(c, extrapolation=mode) for name, c in chis.items()}
                              for chis in (self.chi, self.own))

    def __getstate__(self) -> dict:
        # the table evaluator holds thread-local scratch space: rebuilt where the
        # model lands (a Dask or Spark worker), never pickled
        return {**self.__dict__, "_tables": None}

    @property
    def n_components(self) -> int:
        return len(self.k)

    @property
    def n_outputs(self) -> int:
        """M: the outputs decouple() takes (N, or more with a projection)."""
        return self.n_components if self.projection is None else self.projection.shape[1]

    def project(self, u: np.ndarray) -> np.ndarray:
        """v = P u (n, N) of outputs (n, M) for a model with a projection; else u as it is."""
        u = np.asarray(u, dtype=float).reshape(-1, self.n_outputs)
        return u if self.projection is None else u @ self.projection.T

    @property
    def layout(self) -> Layout:
        """The components' labels, load and output columns (axes.py)."""
        return self.settings.layout

    @property
    def warnings(self) -> list[str]:
        return list(self.report.warnings) if self.report is not None else []

    @property
    def full_scale_output(self) -> np.ndarray:
        """|k_a| F_FS,a per output, in the data's output unit: tolerances are fractions of it."""
        return np.abs(self.k) * np.asarray(self.settings.full_scale, dtype=float)

    @property
    def rotation(self) -> np.ndarray | None:
        """The transform after eq. (11): the config's rotation (N x N), or a frame's 6 x 6."""
        if self.settings.frame is not None:
            return self.settings.frame.matrix()
        r = self.settings.rotation
        return None if r is None else np.asarray(r, dtype=float)

    @property
    def imported(self) -> bool:
        """A linear model without chi: a factory matrix read from a file (data/ati_cal.py)."""
        return self.method == "linear" and not self.chi

    @property
    def n_inputs(self) -> int:
        """A temperature model's raw inputs: the outputs, then a fitted model's temperature."""
        t = self.temperature
        return self.n_outputs + (1 if t is not None and t.external else 0)

    def zero_corrected(self, raw: np.ndarray, offsets: np.ndarray) -> np.ndarray:
        """Outputs as eq. (11) takes them (n, M): ``raw - offsets``; for a model with
        temperature terms, the plan's temperature step on raw inputs (n, ``n_inputs``)
        and their zero reading ``offsets`` (``n_inputs``; all 0: no zero taken)."""
        if self.temperature is None:
            return np.asarray(raw, dtype=float) - offsets
        offsets = np.asarray(offsets, dtype=float)
        step = temperature_step(self.temperature, offsets if offsets.any() else None)
        return step(np.asarray(raw, dtype=float).reshape(-1, step.n_inputs))

    @property
    def calibrated_range(self) -> np.ndarray:
        """Prime-output range of the calibration per component, shape (N, 2) [V].

        An imported factory matrix (no chi; v = P u are its forces, k = 1): the rated
        loads, -max .. +max.
        """
        if self.imported:
            fs = np.abs(self.k) * np.asarray(self.settings.full_scale, dtype=float)
            return np.column_stack([-fs, fs])
        r = np.empty((self.n_components, 2))
        for b in range(self.n_components):
            ranges = [c.input_range for c in self.chi.values() if c.input_axis == b]
            r[b] = (min(lo for lo, _ in ranges), max(hi for _, hi in ranges))
        return r

    @property
    def calibrated_loads(self) -> np.ndarray:
        """The calibrated range over k: the loads it spans, lower end first, shape (N, 2)."""
        return np.sort(self.calibrated_range / self.k[:, None], axis=1)

    def extrapolation_limits(self) -> np.ndarray:
        """The calibrated range widened by RANGE_MARGIN of its span, shape (N, 2).

        An output beyond it is extrapolation (``apply``'s status ``extrapolated``,
        ``validate``'s range, the C header's bits): noise around an end of the
        range (a component at rest at its 0 end) is not.
        """
        r = self.calibrated_range
        margin = RANGE_MARGIN * (r[:, 1] - r[:, 0])
        return np.column_stack([r[:, 0] - margin, r[:, 1] + margin])

    def coupling_errors(self, u: np.ndarray) -> np.ndarray:
        """Measured coupling errors e_a = sum_b chi_ab(u_b) [V] (eq. 1 with eq. 4 at u_(t))."""
        return _coupling_errors(np.asarray(u, dtype=float).reshape(-1, self.n_components),
                                [*self.chi.values(), *self.own.values()])

    def plan(self, *, rotate: bool = True, refine: int | None = None, temperature: bool = True,
             zero=None) -> Plan:
        """The decoupling plan (:mod:`fsdecouple.core.plan`): what every evaluator reads.

        A temperature model's plan takes raw inputs (``n_inputs``), less ``zero``, to T0
        first; ``temperature=False``: outputs at T0 already.
        """
        return model_plan(self, rotate=rotate, refine=self._refine(refine),
                          temperature=temperature, zero=zero)

    def _refine(self, refine: int | None) -> int:
        return self.settings.refine if refine is None else check_refine(refine, "refine")

    def refined(self, refine: int) -> CouplingErrorModel:
        """This model with ``settings.refine = refine`` (``apply --refine K``); tables shared."""
        k = refine_argument(refine, "K")
        if k and self.method == "linear":
            raise ConfigError(f"refine {k}: {LINEAR_NOT_REFINED}", argument="refine")
        settings = replace(self.settings, refine=k)
        model = replace(self, settings=settings)
        model._tables = self._tables
        return model

    def decouple(
        self, u: np.ndarray, *, rotate: bool = True, exact: bool = False, workers: int | None = None,
        refine: int | None = None, converged: np.ndarray | None = None,
        compiled: bool | None = None, temperature=None, zero=None,
    ) -> np.ndarray:
        """Forces [N] from zero-corrected outputs [V] by eq. (11).

        f_a = omega_a^-1[u_a - sum_{b != a} chi_ab(u_b)]; then, if the config gives
        one and ``rotate``, the rotation from the sensor frame to the reference
        frame (end of Section 2.3).  With ``refine`` K > 0 the chi are evaluated
        at estimates of the prime outputs instead of u (second-order refinement,
        :mod:`fsdecouple.core.decouple`).

        Parameters
        ----------
        u : array_like, shape (n, N) or (N,)
            Outputs u_x, u_y, u_z [V], zero-corrected.
        exact : bool
            Evaluate every chi by its kernel sum.  By default the chi surrogates
            stored in the model are used inside their intervals (each within its
            recorded ``max_error`` of the kernel sum) and the kernel sum outside
            them; models without usable surrogates are always exact.
        workers : int, optional
            Threads for the table path; default: the number of cores.
        refine : int, optional
            K fixed-point steps on the prime outputs; default ``settings.refine``
            (0: eq. (11) as the paper writes it).
        converged : ndarray of bool, shape (n,), optional
            Set False for rows whose refinement did not settle (last step above
            ``REFINE_TOLERANCE`` of full-scale output, or not finite): their
            forces are NaN.  All True for K = 0 and for linear models.
        compiled : bool, optional
            Use the compiled table kernel (numba); default: for calls of at least
            ``table_path.COMPILED_WORK`` chi evaluations (2.8 M rows of 3 axes).
        temperature, zero : optional
            A temperature model (core/temperature.py): each row's temperature, ``u`` then
            raw, and a raw zero reading with its temperature (``n_inputs``), both
            corrected to T0 by the plan's first step.  None: ``u`` are at T0 already.
            A model without temperature terms: ``zero`` (M,) [V] makes ``u`` raw outputs,
            less ``zero`` (the plan's zero step, as ``apply --zero``); ``zero="fitted"``:
            less a ``zero: intercept`` model's fitted offsets (``model.zero``), as ``apply``
            with neither ``--tare`` nor ``--zero``.  None: ``u`` are zero-corrected.
        """
        u_arr = np.asarray(u, dtype=float)
        flat = u_arr.reshape(-1, self.n_outputs)
        shape = (*u_arr.shape[:-1], self.n_components) if u_arr.ndim else u_arr.shape
        refine = self._refine(refine)
        before: tuple = ()
        if self.temperature is None and zero is not None:  # raw outputs less a zero (plan.py)
            before = (zero_step(self._zero(zero)),)
        elif temperature is not None or zero is not None:  # raw inputs and the step (plan.py)
            flat, before = temperature_inputs(self.temperature, flat, temperature, zero)
        tables = None if exact else self.fast_decoupler()
        if tables is not None:
            f = tables.decouple(flat, rotate=rotate, workers=workers, refine=refine,
                                converged=converged, compiled=compiled, before=before)
        else:
            plan = self.plan(rotate=rotate, refine=refine, temperature=False)
            if before:
                plan = replace(plan, steps=(*before, *plan.steps), n_outputs=flat.shape[1])
            f = _exact_plan(plan, flat, converged)
        return f.reshape(shape)

    def fast_decoupler(self) -> TableDecoupler | None:
        """The table path (:mod:`fsdecouple.core.table_path`), or None without usable tables."""
        if self.method == "linear":
            return None
        if self._tables is None:  # own-load chi (joint fit) on their input's grid, or none
            self._tables = TableDecoupler.from_plan(model_plan(self, temperature=False)) or False
        return self._tables or None

    def _zero(self, zero) -> np.ndarray:
        """``decouple``'s ``zero`` (M,) [V]: given values, or ``"fitted"``: ``model.zero``."""
        if isinstance(zero, str):
            if zero != "fitted":
                raise ValueError(f"decouple: zero={zero!r}; expected offsets or 'fitted'")
            if self.zero is None:
                from ..errors import ConfigError

                raise ConfigError("the model has no fitted offsets (zero: intercept): give the "
                                  "zero reading's values")
            return np.asarray(self.zero, dtype=float)
        z = np.asarray(zero, dtype=float).reshape(-1)
        if len(z) != self.n_outputs:
            raise ValueError(f"decouple: zero has {len(z)} values for {self.n_outputs} outputs")
        return z

    def decoupler(self, refine: int | None = None, zero=None):
        """A plain-Python function ``(ux, uy, uz) -> (fx, fy, fz)`` for control loops.

        A few microseconds per call: no numpy, no allocation beyond small lists.  Same
        plan, tables and arithmetic as :meth:`decouple` (equal to it within 1e-12 N);
        exact kernel sum for inputs outside the tables and for NaN.  ``refine`` as for
        :meth:`decouple`; a vector that does not settle gives NaN.

        >>> f = model.decoupler()
        >>> fx, fy, fz = f(0.5, 0.01, -0.2)
        A temperature model takes raw inputs (``n_inputs``) to T0 first, no zero subtracted.
        A ``zero: intercept`` model (``model.zero``) takes raw outputs and subtracts its
        fitted offsets first, as the exported C header does until ``set_zero``; ``zero``
        (M,) [V]: subtract these instead (a zero reading of raw outputs).
        """
        refine = self._refine(refine)
        tables = self.fast_decoupler()
        if self.temperature is not None:
            before = (temperature_step(self.temperature),)
        elif zero is not None or self.zero is not None:  # the plan's zero step (plan.py)
            before = (zero_step(self._zero("fitted" if zero is None else zero)),)
        else:
            before = ()
        if tables is not None:
            return tables.one(refine=refine, before=before)
        plan = self.plan(refine=refine, zero=None if zero is None else self._zero(zero))

        def exact_one(*u: float) -> tuple[float, ...]:
            return tuple(_exact_plan(plan, np.array([u], dtype=float))[0].tolist())

        return exact_one

    def decouple_one(self, *u: float) -> tuple[float, ...]:
        """Forces [N] for one output vector [V]; see :meth:`decoupler` for loops."""
        return self.decoupler()(*u)

    def initial_forces(self, u: np.ndarray) -> np.ndarray:
        """Forces with no coupling correction, f = omega^-1(u) per axis (eq. 13 form); M > N:
        the linear forward model's least-squares forces P u."""
        return initial_forces(self.project(u), self.k)
