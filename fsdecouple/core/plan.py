"""The decoupling plan: eq. (11) and every step around it, written once, as data.

A fitted model decouples by a fixed sequence of steps on the raw outputs u (n, M):

1. :class:`TemperatureCorrection`, per channel, the temperature terms
   ``u_i(T0) = (u_i - b_i (T - T0)) / (1 + g_i (T - T0))`` (:mod:`fsdecouple.core.temperature`),
   with the zero read at its own temperature subtracted after (ATIDAQ's bias);
   :class:`InputCorrection`, per channel, ``u_i <- (u_i - offset_i) / gain_i``: the slot
   for other fixed corrections of the raw outputs before eq. (11);
2. :class:`Project`, M > N outputs: v = P u, P = K^+ (:mod:`fsdecouple.fitting.gauges`);
3. :class:`Couple`, eq. (11) with the omega slopes k, each chi_ab as a :class:`Term`
   (its exact kernel sum, continued by its tangents under ``extrapolation: tangent``,
   and its cubic table if it has one), an own-load chi_aa at the measured u_a, and
   K refinement steps (eqs. 5-6); or :class:`Linear`, f = C u, for a linear model;
4. :class:`Rotate`, the sensor frame to the reference frame (end of Section 2.3).

:func:`model_plan` reads the plan off a model; nothing else decides the order.  Every
evaluator reads a plan: the exact numpy path and the table path
(:mod:`fsdecouple.core.decouple`, through :func:`walk`), the one-vector function
(:func:`fsdecouple.core.decouple.one_vector`), the float emulation and the C text of an
exported header (:mod:`fsdecouple.export`).  Each evaluator dispatches on the step
kinds it knows and raises :class:`UnknownStep` for any other, so a step added here
is either evaluated everywhere or refused loudly, never skipped.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from .temperature import correct

# A refined row has settled when its last step, k_a f_a - p_a^K, is at most this
# fraction of each full-scale output.  Under Section 2.1's assumptions it is at most
# (N - 1) 0.05 * 5 % = 0.5 % F.S. at K = 1 (N = 3), tenfold less a step on; above 1 %
# the row is outside the regime known to contract: diverging, not just slow.
REFINE_TOLERANCE = 0.01


class UnknownStep(TypeError):
    """An evaluator met a step kind it does not implement (a bug, never bad input)."""

    def __init__(self, step: Any, evaluator: str):
        super().__init__(f"{evaluator} has no case for a {type(step).__name__} step of the "
                         "decoupling plan (core/plan.py): add one")


@dataclass(frozen=True)
class Term:
    """One chi_ab of eq. (11): output ``out`` = a, input ``inp`` = b (own-load when a == b).

    ``chi(u)`` [output unit] is the exact corrected coupling function (eq. 4): the
    kernel sum (eq. 10), continued by its tangents beyond the calibrated range under
    ``extrapolation: tangent``; ``chi.slope(u)`` its derivative.  ``table``: its cubic
    Hermite table (:class:`fsdecouple.core.surrogate.ChiSurrogate`), or None.
    """

    out: int
    inp: int
    chi: Any = field(compare=False)
    table: Any = field(default=None, compare=False)

    @property
    def own(self) -> bool:
        return self.out == self.inp


@dataclass(frozen=True, eq=False)
class InputCorrection:
    """Per raw output i: ``u_i <- (u_i - offset_i) / gain_i``, before anything else.

    ``zero``: the step is the zero subtracted from raw outputs (gain 1): a ``zero:
    intercept`` model's fitted offsets by default (:func:`zero_step`), which the C
    header's ``set_zero(u_zero)`` replaces by a zero reading of the controller's.
    """

    offset: np.ndarray  # (M,) [output unit]
    gain: np.ndarray  # (M,) [1]
    zero: bool = False

    @property
    def n_inputs(self) -> int:
        return len(self.offset)


def zero_step(offsets) -> InputCorrection:
    """The plan's zero on raw outputs: ``u <- u - offsets`` (M,) [output unit], as ``apply``
    subtracts a tare, ``--zero`` or a ``zero: intercept`` model's fitted offsets."""
    offsets = np.asarray(offsets, dtype=float)
    return InputCorrection(offsets, np.ones(len(offsets)), zero=True)


@dataclass(frozen=True, eq=False)
class TemperatureCorrection:
    """Per raw input i: ``u_i <- (u_i - b_i (T - T0)) / (1 + g_i (T - T0))``, T = u[channel].

    The formula is :func:`fsdecouple.core.temperature.correct` (ATI's form); b and g are 0
    at ``channel``, which keeps its temperature.  ``zero``: a zero reading of the same
    inputs (its temperature at ``channel``), corrected alike at its own temperature and
    subtracted after, as ATIDAQ's bias does (F = W (c(G, T) - c(G_bias, T_bias))); the
    temperature input becomes T - T_zero.  None: nothing subtracted.  ``external``: the
    temperature is an input after the model's outputs (a fitted model), dropped after
    the correction; otherwise it is one of them (an ATI thermistor, whose matrix column
    is 0).
    """

    channel: int
    t0: float  # [temperature unit]
    b: np.ndarray  # (inputs,) [output unit / temperature unit]
    g: np.ndarray  # (inputs,) [1 / temperature unit]
    zero: np.ndarray | None = None  # (inputs,) [output unit; temperature unit at channel]
    external: bool = False
    span: tuple[float, float] | None = None  # calibrated temperatures: beyond, extrapolated

    @property
    def n_inputs(self) -> int:
        return len(self.b)

    def zero_at_t0(self, dtype=np.float64) -> np.ndarray | None:
        """The zero reading corrected at its own temperature (inputs,), or None."""
        if self.zero is None:
            return None
        z = np.asarray(self.zero, dtype=float).astype(dtype)
        return correct(z[None, :], z[None, self.channel], self.t0, self.b, self.g)[0]

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """The step on inputs ``x`` (n, inputs), in x's dtype."""
        y = correct(x, x[:, self.channel], self.t0, self.b, self.g)
        z = self.zero_at_t0(x.dtype)
        if z is not None:
            y = y - z
        return np.delete(y, self.channel, axis=1) if self.external else y


def temperature_step(terms, zero=None) -> TemperatureCorrection:
    """The plan's step of a model's :class:`~fsdecouple.core.temperature.TemperatureTerms`;
    ``zero``: a raw zero reading of the inputs (outputs, and the temperature at its channel)."""
    b, g = np.asarray(terms.b, float), np.asarray(terms.g, float)
    if terms.external:
        b, g = np.append(b, 0.0), np.append(g, 0.0)
    return TemperatureCorrection(terms.channel, float(terms.t0), b, g,
                                 None if zero is None else np.asarray(zero, dtype=float),
                                 terms.external, terms.span)


def temperature_inputs(terms, u: np.ndarray, temperature, zero) -> tuple[np.ndarray, tuple]:
    """``model.decouple(u, temperature=, zero=)``: the plan's raw inputs (the outputs ``u``
    (n, M), and the temperature after them or at an ATI thermistor's place) and its
    temperature step, as the plan's first."""
    if terms is None:
        from ..errors import ConfigError

        raise ConfigError("the model has no temperature terms: temperature and zero are for a "
                          "model fitted or imported with them")
    if temperature is None:
        raise TypeError("decouple: zero is the raw zero of a temperature model: give temperature")
    t = np.broadcast_to(np.asarray(temperature, dtype=float), u.shape[:1])
    if terms.external:
        x = np.column_stack([u, t])
    else:
        x = u.copy()
        x[:, terms.channel] = t
    return x, (temperature_step(terms, zero),)


@dataclass(frozen=True, eq=False)
class Project:
    """v = P u: the least-squares loads of M > N outputs (fitting/gauges.py)."""

    matrix: np.ndarray  # (N, M)


@dataclass(frozen=True, eq=False)
class Couple:
    """Eq. (11) with own-load chi and K refinement steps (module doc of core/decouple.py).

    ``terms``: the cross chi in the model's order (output-major), then the own-load chi;
    ``full_scale_output``: |k_a| F_FS,a, to which the settled test and the tables' gate
    are relative.
    """

    k: np.ndarray  # (N,) [output unit per load unit]
    terms: tuple[Term, ...]
    refine: int = 0
    full_scale_output: np.ndarray | None = None  # (N,) [output unit]; None: 1 each

    @property
    def step_tol(self) -> np.ndarray:
        """A refined row's largest last step per output: REFINE_TOLERANCE of its full scale."""
        fs = np.ones(len(self.k)) if self.full_scale_output is None else self.full_scale_output
        return REFINE_TOLERANCE * np.asarray(fs, dtype=float)

    @property
    def cross(self) -> tuple[Term, ...]:
        return tuple(t for t in self.terms if not t.own)

    @property
    def own(self) -> tuple[Term, ...]:
        return tuple(t for t in self.terms if t.own)


@dataclass(frozen=True, eq=False)
class Linear:
    """f = C u: a linear model's least-squares calibration matrix (fit --method linear)."""

    matrix: np.ndarray  # (N, M)


@dataclass(frozen=True, eq=False)
class Rotate:
    """f <- R f: the sensor frame to the reference frame."""

    matrix: np.ndarray  # (N, N)


@dataclass(frozen=True, eq=False)
class Plan:
    """The steps from raw outputs (n, ``n_outputs``) to forces (n, ``n_components``)."""

    steps: tuple
    n_outputs: int
    n_components: int

    @property
    def couple(self) -> Couple | None:
        return next((s for s in self.steps if isinstance(s, Couple)), None)

    @property
    def terms(self) -> tuple[Term, ...]:
        c = self.couple
        return () if c is None else c.terms

    def step(self, kind: type):
        """The step of ``kind``, or None."""
        return next((s for s in self.steps if isinstance(s, kind)), None)

    def with_terms(self, terms) -> Plan:
        """The same plan with the coupling step's terms replaced (other tables)."""
        return replace(self, steps=tuple(replace(s, terms=tuple(terms)) if isinstance(s, Couple)
                                         else s for s in self.steps))

    def inserted(self, step) -> Plan:
        """The plan with ``step`` on the raw outputs, after its other input corrections."""
        i = next((i for i, s in enumerate(self.steps) if not isinstance(s, InputCorrection)),
                 len(self.steps))
        return replace(self, steps=(*self.steps[:i], step, *self.steps[i:]))


def model_plan(model, *, rotate: bool = True, refine: int | None = None,
               corrections: tuple = (), temperature: bool = True, zero=None) -> Plan:
    """The plan of a :class:`~fsdecouple.core.model.CouplingErrorModel` (its own tables).

    ``corrections``: steps applied to the raw outputs first (:class:`InputCorrection`).
    ``temperature``: a model with temperature terms corrects its raw inputs (outputs and
    the temperature) first, subtracting ``zero`` (a raw zero reading of the same inputs)
    after; a ``zero: intercept`` model (``model.zero``) subtracts ``zero`` (raw outputs),
    by default its fitted offsets, first (:func:`zero_step`); False: the outputs are taken
    as corrected already (at T0, zero removed).
    """
    n = model.n_components
    n_in = model.n_outputs
    steps: list = list(corrections)
    terms = getattr(model, "temperature", None)
    if terms is not None and temperature:
        steps.insert(0, temperature_step(terms, zero))
        n_in = steps[0].n_inputs
    elif temperature and (zero is not None or getattr(model, "zero", None) is not None):
        steps.insert(0, zero_step(model.zero if zero is None else zero))
    if model.method == "linear" and getattr(model, "imported", False):
        # a factory matrix (data/ati_model.py): v = P u are its forces (k = 1), f = I v, so
        # the range (+-max) is checked on them, as apply's "extrapolated" does
        steps += [Project(np.asarray(model.projection, dtype=float)), Linear(np.eye(n))]
    elif model.method == "linear":
        steps.append(Linear(np.asarray(model.matrix, dtype=float)))
    else:
        if model.projection is not None:
            steps.append(Project(np.asarray(model.projection, dtype=float)))
        chis = [*model.chi.values(), *model.own.values()]  # own-load chi_aa last
        terms = tuple(Term(c.output_axis, c.input_axis, c, c.surrogate) for c in chis)
        k = np.asarray(model.k, dtype=float)
        steps.append(Couple(k, terms, model.settings.refine if refine is None else int(refine),
                            model.full_scale_output))
    rotation = model.rotation
    if rotate and rotation is not None:
        steps.append(Rotate(np.asarray(rotation, dtype=float)))
    return Plan(tuple(steps), n_in, n)


def matrix_product(m: np.ndarray, x: np.ndarray) -> np.ndarray:
    """x @ m.T; below double precision each row's products added left to right, as the C."""
    if x.dtype == np.float64:
        return x @ np.asarray(m, dtype=float).T
    m = np.asarray(m).astype(x.dtype)
    out = np.empty((len(x), m.shape[0]), dtype=x.dtype)
    for i in range(m.shape[0]):
        acc = m[i, 0] * x[:, 0]
        for j in range(1, m.shape[1]):
            acc = acc + m[i, j] * x[:, j]
        out[:, i] = acc
    return out


def walk(plan: Plan, u, couple, *, dtype=np.float64, evaluator: str = "the numpy walk"):
    """The plan's steps on outputs ``u`` (n, M), in ``dtype``; ``couple(step, x)`` evaluates
    the :class:`Couple` step (exact, tables or float), the other kinds are matrix products."""
    x = np.asarray(u, dtype=dtype).reshape(-1, plan.n_outputs)
    for step in plan.steps:
        if isinstance(step, TemperatureCorrection):
            x = step(x)
        elif isinstance(step, InputCorrection):
            x = (x - np.asarray(step.offset).astype(dtype)) / np.asarray(step.gain).astype(dtype)
        elif isinstance(step, Project | Linear | Rotate):
            x = matrix_product(step.matrix, x)
        elif isinstance(step, Couple):
            x = couple(step, x)
        else:
            raise UnknownStep(step, evaluator)
    return x
