"""The interval data a model file carries (``report.certificate["interval"]``): the
stored sweep model's evaluator and the checks that refuse data a fit cannot have
written (issue 33).

:class:`SweepModel` evaluates the least-squares model of the single-axis sweeps that
:mod:`fsdecouple.evaluation.sweep_model` fits (its outputs, Jacobian, forces and the
error's variance at a row); :func:`check_interval_data` is what the model file checks
when it loads (:mod:`fsdecouple.core.modelfile`) and the intervals again when they
are used (:mod:`fsdecouple.evaluation.intervals`).  Here, in ``core``, so that loading
a model needs neither fitting nor evaluation.
"""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np

from ..errors import InputError
from .model import RANGE_MARGIN, CouplingErrorModel

MAX_DEGREE = 7  # of a g_ab; 9 and 12 measured alike (docs/design/intervals.md)
NEWTON_STEPS = 30
NEWTON_TOLERANCE = 1e-10  # of the largest calibrated load: a row has settled (the noise: ~1e-4)

# [full scales of the component] a held-out score times its sigma, an expanded uncertainty
# U or a model error beyond this is no calibration: an edited file (issue 34: sigma 1e300,
# scores 1e308 gave interval bounds of 1e300 with status ok)
MAX_FULL_SCALES = 1e3
# Bounds on what a fit writes (a file beyond them was edited), each with wide margin:
SPAN_AGREEMENT = 0.1  # of the span: its ends against the model's calibrated loads (~1e-3)
OWN_SLOPE = (0.5, 2.0)  # dg_bb/df_b over k_b along the span (0.996-1.005 measured)
SLOPE_GRID = 33  # loads along each span at which it is judged
MEAN_SQUARE = (0.5, 2.0)  # a sweep model's studentised residuals: E z^2 = 1 (0.9-1.03 measured)
# normalised held-out scores and deviations: a held-out error carries a reading's own
# noise, so their mean square is about 1 or more (1.06-39 measured); and a sweep model's
# reading noise over the held-out sigma (0.98-13 measured)
MIN_MEAN_SQUARE = 0.01
MIN_NOISE_RATIO = 0.1


class SweepModel:
    """The stored model as polynomials in each s_b = f_b / L_b, per output a and load b,
    coefficients of s^0, s^1, ... (padded to one degree): g_ab, its derivative and the
    model's variance x(s)' C_ab x(s) (a polynomial of twice the degree)."""

    def __init__(self, doc: dict[str, Any]):
        self.peak = np.asarray(doc["peak"], dtype=float)
        self.span = np.asarray(doc["span"], dtype=float).reshape(-1, 2)
        n = self.peak.size
        d = max(len(c) for row in doc["shape"] for c in row)
        self.g = np.zeros((n, n, d + 1))  # [a, b, power]: g_ab(0) = 0
        self.quad = np.zeros((n, n, 2 * d + 1))  # x' C x = sum_{k,l} C_kl s^(k+l)
        for b in range(n):
            for a in range(n):
                beta = np.asarray(doc["shape"][b][a], dtype=float)
                cov = np.asarray(doc["covariance"][b][a], dtype=float).reshape(beta.size, beta.size)
                self.g[a, b, 1:beta.size + 1] = beta
                k = np.arange(1, beta.size + 1)
                np.add.at(self.quad[a, b], (k[:, None] + k[None, :]).ravel(), cov.ravel())
        powers = np.arange(1, d + 1)
        self.slope = self.g[..., 1:] * powers / self.peak[None, :, None]  # dg_ab/df_b
        self.noise = np.asarray(doc["noise_variance"], dtype=float)

    def inside(self, f: np.ndarray) -> np.ndarray:
        """Rows (of forces ``f``, (n, N)) whose every load lies in the calibrated span
        widened by ``RANGE_MARGIN`` of it (the margin ``apply``'s status ``extrapolated``
        gives the outputs): beyond it the polynomials extrapolate, and their centre is
        not used."""
        margin = RANGE_MARGIN * (self.span[:, 1] - self.span[:, 0])
        with np.errstate(invalid="ignore"):
            return np.all((f >= self.span[:, 0] - margin) & (f <= self.span[:, 1] + margin), axis=1)

    def largest_ratio(self) -> float:
        """rho = sqrt(model's variance / reading's) at its largest where every load is at
        an end of its span or 0 (3^N rows): the range of the half-widths' grid, the same
        for every block of a log."""
        corners = np.array(list(itertools.product(*[(lo, 0.0, hi) for lo, hi in self.span])))
        reading, model = self.variances(corners)
        with np.errstate(all="ignore"):
            rho = np.sqrt(model / reading)
        return float(np.max(rho[np.isfinite(rho)], initial=0.0))

    def outputs(self, f: np.ndarray) -> np.ndarray:
        """g(f) = sum_b g_ab(f_b), shape (n, N) [output unit]."""
        return _sum_of_polynomials(self.g, f / self.peak)

    def jacobian(self, f: np.ndarray) -> np.ndarray:
        """J_ab = dg_a/df_b at ``f``, shape (n, N, N)."""
        x = _powers(f / self.peak, self.slope.shape[2] - 1)
        return np.stack([x[:, b] @ self.slope[:, b].T for b in range(self.peak.size)], axis=2)

    def forces(self, u: np.ndarray, start: np.ndarray) -> np.ndarray:
        """The forces whose outputs are ``u`` (zero-corrected, (n, N)), from ``start``;
        NaN where a row does not settle.  Newton's method with the Jacobian of the start
        kept (the chord method: ``start`` is eq. (11)'s forces, within the noise of the
        solution, where J hardly moves), one inverse a row instead of one a step."""
        f = np.where(np.isfinite(start), start, 0.0)
        settled = np.zeros(len(u), dtype=bool)
        tol = NEWTON_TOLERANCE * self.peak.max()
        with np.errstate(all="ignore"):
            inv, ok = _inverse(self.jacobian(f))
            active = np.flatnonzero(np.isfinite(u).all(axis=1) & ok)
            for _ in range(NEWTON_STEPS):
                if not active.size:
                    break
                step = np.einsum("nab,nb->na", inv[active], u[active] - self.outputs(f[active]))
                f[active] += step
                small = np.abs(step).max(axis=1) <= tol
                settled[active[small]] = True
                active = active[~small & np.isfinite(f[active]).all(axis=1)]
        return np.where(settled[:, None], f, np.nan)

    def variances(self, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """At forces ``f`` (n, N): the variance of each force's error from the reading
        and from the model, each (n, N) [load unit^2]; NaN where J is singular."""
        with np.errstate(all="ignore"):
            x = np.nan_to_num(f)
            model = self.noise * _sum_of_polynomials(self.quad, x / self.peak)
            inv, ok = _inverse(self.jacobian(x))
            sq = inv ** 2
            reading = sq @ self.noise
            shared = np.einsum("nac,nc->na", sq, model)
        bad = ~ok | ~np.isfinite(f).all(axis=1)
        reading[bad] = np.nan
        shared[bad] = np.nan
        return reading, shared


def _powers(s: np.ndarray, degree: int) -> np.ndarray:
    """s^0 .. s^degree of every load, shape (n, B, degree + 1)."""
    out = np.empty((*s.shape, degree + 1))
    out[..., 0] = 1.0
    for k in range(1, degree + 1):
        np.multiply(out[..., k - 1], s, out=out[..., k])
    return out


def _sum_of_polynomials(c: np.ndarray, s: np.ndarray) -> np.ndarray:
    """sum_b sum_k c[a, b, k] s_b^k for every row, shape (n, A): one product of the
    powers (n, B (d + 1)) with the coefficients."""
    x = _powers(s, c.shape[2] - 1)
    return x.reshape(len(s), -1) @ c.reshape(c.shape[0], -1).T


def _inverse(jac: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """J^-1 of every row, and which rows' J is invertible: singular where |det J| is
    below 1e-12 of the product of its rows' norms (those rows: the identity's).  Three
    components: the adjugate, whose columns are the rows' cross products."""
    n = jac.shape[-1]
    finite = np.isfinite(jac).all(axis=(1, 2))
    safe = np.where(finite[:, None, None], jac, np.eye(n))
    scale = np.prod(np.linalg.norm(safe, axis=2), axis=1)
    if n == 3:
        r0, r1, r2 = safe[:, 0], safe[:, 1], safe[:, 2]
        adj = np.stack([np.cross(r1, r2), np.cross(r2, r0), np.cross(r0, r1)], axis=2)
        det = np.einsum("ni,ni->n", r0, adj[:, :, 0])
        ok = finite & (np.abs(det) > 1e-12 * scale)
        inv = adj / np.where(ok, det, 1.0)[:, None, None]
        inv[~ok] = np.eye(n)
        return inv, ok
    ok = finite & (np.abs(np.linalg.det(safe)) > 1e-12 * scale)
    safe[~ok] = np.eye(n)
    return np.linalg.inv(safe), ok


def check_sweep_model(doc: Any, labels, model: CouplingErrorModel | None = None) -> None:
    """Refuse a stored sweep model a fit cannot have written (None: there is none):
    per component a peak > 0 that is the largest |load| of its span, per component and
    output a shape of 1 to ``MAX_DEGREE`` finite numbers and its covariance, symmetric
    and positive semi-definite, per output a noise variance > 0, and the reading's and
    the model's standard deviations finite and at most ``MAX_FULL_SCALES`` spans where
    the calibration loaded (each end of each span, one component at a time).

    With the ``model`` it belongs to: the span's ends within ``SPAN_AGREEMENT`` of the
    span from the model's calibrated loads (a span edited with its peak, both 1e-300,
    put every log row beyond it: bounds NaN, status ok), and each own-load slope
    dg_bb/df_b within ``OWN_SLOPE`` of k_b along its span (a shape edited to a root
    inside the span moved the centre and widened the bounds 50-fold)."""
    if doc is None:
        return
    n = len(labels)

    def damaged(what: str, value, expected: str) -> InputError:
        return _damaged(f"least_squares {what} is {value!r}, expected {expected}")

    if not isinstance(doc, dict):
        raise damaged("", doc, "the sweep model's fields")
    for key in ("peak", "noise_variance"):
        v = doc.get(key)
        if not (isinstance(v, list) and len(v) == n and all(_number(x) and x > 0 for x in v)):
            raise damaged(key, v, f"{n} finite numbers > 0")
    v = doc.get("span")
    if not (isinstance(v, list) and len(v) == n
            and all(isinstance(r, list) and len(r) == 2 and all(_number(x) for x in r) and r[0] < r[1]
                    for r in v)):
        raise damaged("span", v, f"{n} pairs of finite loads, the lower first")
    for key in ("shape", "covariance"):
        v = doc.get(key)
        if not (isinstance(v, list) and len(v) == n and all(isinstance(r, list) and len(r) == n for r in v)):
            raise damaged(key, v, f"{n} x {n} entries")
    for b, axis in enumerate(labels):
        for a in range(n):
            beta, cov = doc["shape"][b][a], doc["covariance"][b][a]
            where = f"{{load {axis}, output {a + 1}}}"
            if not (isinstance(beta, list) and 1 <= len(beta) <= MAX_DEGREE
                    and all(_number(x) for x in beta)):
                raise damaged(f"shape {where}", beta, f"1 to {MAX_DEGREE} finite numbers")
            k = len(beta)
            if not (isinstance(cov, list) and len(cov) == k
                    and all(isinstance(r, list) and len(r) == k and all(_number(x) for x in r)
                            for r in cov)):
                raise damaged(f"covariance {where}", "...", f"{k} x {k} finite numbers")
            c = np.asarray(cov, dtype=float)
            # as fitted, R^-1 R^-T: symmetric to the bit and positive semi-definite
            size = np.abs(c).max(initial=0.0)
            if not (np.abs(c - c.T).max(initial=0.0) <= 1e-6 * size
                    and np.linalg.eigvalsh(c).min() >= -1e-6 * size):
                raise damaged(f"covariance {where}", "...",
                              "a symmetric positive semi-definite matrix")
    span = np.asarray(doc["span"], dtype=float)
    for b, axis in enumerate(labels):
        largest = np.abs(span[b]).max()
        if abs(doc["peak"][b] - largest) > 1e-12 * largest:
            raise damaged(f"peak of {axis}", doc["peak"][b],
                          f"the largest |load| of its span, {float(largest)!r}")
    sweeps = SweepModel(doc)
    if model is not None:
        loads = model.calibrated_loads
        for b, axis in enumerate(labels):
            if np.isfinite(loads[b]).all() \
                    and np.abs(span[b] - loads[b]).max() > SPAN_AGREEMENT * (span[b, 1] - span[b, 0]):
                raise damaged(f"span of {axis}", doc["span"][b],
                              f"the calibrated loads, [{loads[b, 0]:.6g}, {loads[b, 1]:.6g}]")
            along = np.zeros((SLOPE_GRID, n))
            along[:, b] = np.linspace(*span[b], SLOPE_GRID)
            with np.errstate(all="ignore"):
                ratio = sweeps.jacobian(along)[:, b, b] / model.k[b]
            good = (ratio >= OWN_SLOPE[0]) & (ratio <= OWN_SLOPE[1])
            if not good.all():  # the slope found, so an edited k or shape shows which
                worst = float(ratio[np.argmin(good)])
                raise _damaged(f"least_squares own-load slope of {axis} is {worst:.4g} times "
                               f"omega's k_{axis} ({float(model.k[b]):.6g}) at some load of its "
                               f"span, expected {OWN_SLOPE[0]:g}-{OWN_SLOPE[1]:g} times: the "
                               "interval data and the model's slopes disagree")
    ends = np.zeros((2 * n + 1, n))
    for b in range(n):
        ends[2 * b + 1:2 * b + 3, b] = span[b]
    reading, shared = sweeps.variances(ends)
    limit = MAX_FULL_SCALES * (span[:, 1] - span[:, 0])
    for what, v in (("reading's", reading), ("model's", shared)):
        with np.errstate(invalid="ignore"):
            sd = np.sqrt(v)
        bad = ~(np.isfinite(sd) & (sd <= limit))
        if bad.any():
            raise damaged(f"{what} standard deviation at the span's ends", float(sd[bad][0]),
                          f"finite numbers of at most {MAX_FULL_SCALES:g} spans")


def _damaged(detail: str) -> InputError:
    """The one refusal of interval data a fit cannot have written (issue 33); ``detail``
    kept apart for fit, which asks the same checks before it writes (modelfile)."""
    err = InputError(f"intervals: the model file's interval data are damaged ({detail}); "
                     "refit the model", argument="interval")
    err.detail = detail
    return err


def _number(x) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)


def check_interval_data(cal: Any, labels, model: CouplingErrorModel | None = None) -> None:
    """Refuse interval data a fit cannot have written: ``load_variance``, ``first_step``
    and ``zero_variance`` must be finite, >= 0, > 0 and >= 0 respectively,
    ``deviations`` finite and sorted (and there beside a sweep model) with a mean square
    of a fit's (``MEAN_SQUARE`` beside a sweep model, else at least
    ``MIN_MEAN_SQUARE``), and ``least_squares`` as :func:`check_sweep_model` checks it.

    With the ``model`` it belongs to (the model file checks at load; the held-out
    scores and sigma it checks itself): the deviations times sigma at most
    ``MAX_FULL_SCALES`` full scales, a sweep model's reading noise at least
    ``MIN_NOISE_RATIO`` of sigma, and the sweep model against the model."""
    def bad(what: str, value) -> InputError:
        return _damaged(f"{what} is {value!r}, expected a finite number "
                        f"{'>= 0' if 'variance' in what else '> 0'}")

    for axis in labels:
        c = cal["components"][axis]
        if "load_variance" in c and not (_number(c["load_variance"]) and c["load_variance"] >= 0):
            raise bad(f"load_variance of {axis}", c["load_variance"])
    swept = cal.get("least_squares")
    check_sweep_model(swept, labels, model)
    deviations = cal.get("deviations")
    if deviations is None and swept is not None:
        raise _damaged("deviations are missing beside least_squares")
    if deviations is not None and not _ascending(deviations):
        raise _damaged("deviations are not finite numbers in ascending order")
    if deviations is not None:
        with np.errstate(over="ignore"):
            square = float(np.mean(np.square(deviations)))
        lo, hi = MEAN_SQUARE if swept is not None else (MIN_MEAN_SQUARE, math.inf)
        if not lo <= square <= hi:
            expected = (f"{lo:g} to {hi:g}, as studentised residuals have" if swept is not None
                        else f"at least {lo:g}: held-out errors carry a reading's noise")
            raise _damaged(f"deviations' mean square is {square!r}, expected {expected}")
    if model is not None:
        _check_against_sigma(cal, labels, model, deviations, swept)
    if deviations is not None and swept is None:
        shares = cal.get("zero_variance")
        if not isinstance(shares, dict):
            raise bad("zero_variance", shares)
        for axis, value in shares.items():
            if axis not in labels or not (_number(value) and value >= 0):
                raise bad(f"zero_variance of {axis}", value)
    shift = cal.get("zero_shift")
    if shift is not None:
        if not isinstance(shift, dict):
            raise bad("zero_shift", shift)
        for axis, row in shift.items():
            if axis not in labels or not (isinstance(row, list) and len(row) == len(labels)
                                          and all(_number(x) for x in row)):
                raise _damaged(f"zero_shift of {axis} is {row!r}, expected {len(labels)} finite "
                               "numbers")
    steps = cal.get("first_step")
    if steps is not None:
        if not isinstance(steps, dict):
            raise bad("first_step", steps)
        for axis, value in steps.items():
            if axis not in labels or not (_number(value) and value > 0):
                raise bad(f"first_step of {axis}", value)


def _check_against_sigma(cal, labels, model: CouplingErrorModel, deviations, swept) -> None:
    """The deviations and a sweep model's noise against each component's held-out sigma."""
    sigma = np.array([cal["components"][a]["sigma"] for a in labels], dtype=float)
    limit = MAX_FULL_SCALES * np.asarray(model.settings.full_scale, dtype=float)
    if deviations is not None:
        largest = max(abs(deviations[0]), abs(deviations[-1]))
        worst = int(np.argmax(largest * sigma / limit))
        if largest * sigma[worst] > limit[worst]:
            raise _damaged(f"deviation {largest!r} times {labels[worst]}'s sigma {sigma[worst]!r} "
                           f"is more than {MAX_FULL_SCALES:g} full scales")
    if swept is not None:
        noise = np.sqrt(np.asarray(swept["noise_variance"], dtype=float)) / np.abs(model.k)
        low = noise < MIN_NOISE_RATIO * sigma
        if low.any():
            a = int(np.flatnonzero(low)[0])
            raise _damaged(f"least_squares noise_variance of output {a + 1} is "
                           f"{swept['noise_variance'][a]!r}, expected a reading noise of at least "
                           f"{MIN_NOISE_RATIO:g} of {labels[a]}'s held-out sigma")


def _ascending(values) -> bool:
    """A non-empty list of finite numbers (no bools) in ascending order, compared at C
    speed (a model file holds ~10^3 deviations, checked at every load)."""
    if not (numbers(values) and values):
        return False
    v = np.asarray(values, dtype=float)
    return bool(np.isfinite(v).all() and (v[1:] >= v[:-1]).all())


_PLAIN_NUMBERS = frozenset({int, float})


def numbers(v: Any, n: int | None = None) -> bool:
    """A list (of ``n`` items) of numbers, bools not counted as numbers.

    The types of a parsed list are gathered at C speed (a certificate holds ~10^4
    numbers); only a list holding other types (a float subclass, say) is checked
    item by item.
    """
    return isinstance(v, list) and (n is None or len(v) == n) and (
        set(map(type, v)) <= _PLAIN_NUMBERS
        or all(isinstance(x, int | float) and not isinstance(x, bool) for x in v))
