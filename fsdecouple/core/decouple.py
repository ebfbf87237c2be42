"""Eq. (11), once, over (n, N) arrays: the exact evaluator of a decoupling plan.

    f_a = omega_a^-1 [u_a - sum_{b != a} chi_ab(u_b)]                    eq. (11)

with omega_a^-1(v) = v / k_aa (eq. 13 form).  N is the number of components
(len(k)); nothing here knows their names.  The steps around eq. (11) (input
corrections, the M > N projection, the rotation) and their order are the plan's
(:mod:`fsdecouple.core.plan`); this module evaluates its :class:`~fsdecouple.core.plan.Couple`
step with every chi as given (the kernel sum, continued by its tangents; or any
other callable such as the RBF baseline's networks).  The table path
(:mod:`fsdecouple.core.table_path`) evaluates the same plan from the chi tables and
hands the rows outside them back here.

A joint fit may add an own-load chi_aa(u_a) (:mod:`fsdecouple.fitting.joint`): it is
subtracted like the others, always at the measured u_a (it models the outputs as
measured), on every path.

Second-order refinement (``refine = K``; docs/apply.md, "Second-order refinement"):
eq. (11) evaluated at estimates p of the prime outputs instead of u (eq. 5-6),

    p^0 = u,   p_b^(j+1) = u_b - chi_bb(u_b) - sum_{c != b} chi_bc(p_c^j)   (j = 0 .. K - 1)
    f_a = [u_a - chi_aa(u_a) - sum_{b != a} chi_ab(p_b^K)] / k_aa,  so k_a f_a = p_a^(K+1).

A contraction when (N - 1) max|chi'| < 1.  K = 0 is eq. (11), bit for bit, on
every path.  A row whose last step k f - p^K is not finite or above
REFINE_TOLERANCE F.S. gets NaN forces and converged = False, never silent forces.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Protocol

import numpy as np

from .plan import REFINE_TOLERANCE, Couple, Plan, Rotate, Term, walk

__all__ = ["PROMISE", "MAX_SURROGATE_ERROR", "REFINE_TOLERANCE", "coupling_errors", "couple",
           "decouple_exact", "exact", "initial_forces", "settled", "usable"]

# The table path promises forces within PROMISE of the exact kernel sum, as a
# fraction of each output's full scale |k_a| F_FS,a (so 1e-9 V on the paper's sensor,
# whose full-scale outputs are about 1 V, and the same fraction in mV or counts).
# An output adds N - 1 chi, and a surrogate's recorded max_error is the largest
# error found on its check grid, which at the kernel sum's own rounding noise can
# be exceeded a little between check points.  So a surrogate is used only if its
# recorded error is at most a quarter of the promise (fit builds them to a tenth).
PROMISE = 1e-9
MAX_SURROGATE_ERROR = PROMISE / 4


class ChiFunction(Protocol):
    """A corrected coupling function chi_ab (eq. 4): output a, input b."""

    output_axis: int
    input_axis: int

    def __call__(self, u: np.ndarray) -> np.ndarray: ...


def coupling_errors(u: np.ndarray, chis: Iterable[ChiFunction]) -> np.ndarray:
    """Measured coupling errors e_a = sum_{b != a} chi_ab(u_b) (eq. 1 with eq. 4 at u_(t)).

    Summed in the order of ``chis`` (output-major, inputs ascending).
    """
    e = np.zeros_like(u)
    for c in chis:
        e[:, c.output_axis] += c(u[:, c.input_axis])
    return e


def _exact_chi(term: Term, x: np.ndarray) -> np.ndarray:
    return term.chi(x)


def couple(step: Couple, u: np.ndarray, chi=_exact_chi) -> tuple[np.ndarray, np.ndarray]:
    """Eq. (11) of a plan's coupling step on prime outputs ``u`` (n, N), in u's dtype.

    ``chi(term, x)`` evaluates one chi (default: exactly).  Returns ``(f, ok)``: the
    forces before any rotation, and per row whether the refinement settled (module
    doc); the caller decides what an unsettled row gets.  Each output's chi are
    summed in the order of the plan's terms.
    """
    dtype = u.dtype

    def errors(x: np.ndarray, terms) -> np.ndarray:
        e = np.zeros(x.shape, dtype=dtype)
        for t in terms:
            e[:, t.out] += np.asarray(chi(t, x[:, t.inp]), dtype=dtype)
        return e

    own, cross = step.own, step.cross
    with np.errstate(invalid="ignore", over="ignore"):  # an infinite row stays inf or NaN
        base = u - errors(u, own) if own else u  # the own-load chi always at the measured u_a
        p = u
        for _ in range(step.refine):
            p = base - errors(p, cross)
        kf = base - errors(p, cross)  # = p^(K+1)
        f = kf / np.asarray(step.k).astype(dtype)
        if not step.refine:
            return f, np.ones(len(f), dtype=bool)
        return f, settled(kf - p, step.step_tol)


def exact(plan: Plan, u: np.ndarray, converged: np.ndarray | None = None) -> np.ndarray:
    """Forces of ``plan`` for raw outputs ``u`` (n, M) with every chi evaluated exactly.

    Rows whose refinement does not settle get NaN forces and False in ``converged``.
    """
    ok_rows = np.ones(np.asarray(u).reshape(-1, plan.n_outputs).shape[0], dtype=bool)

    def step(c: Couple, x: np.ndarray) -> np.ndarray:
        f, ok = couple(c, x)
        f[~ok] = np.nan
        ok_rows[:] = ok
        return f

    f = walk(plan, u, step, evaluator="the exact path")
    if converged is not None:
        converged[:] = ok_rows
    return f


def decouple_exact(u: np.ndarray, k: np.ndarray, chis: Iterable[ChiFunction],
                   rotation: np.ndarray | None = None, *, refine: int = 0,
                   full_scale_output=1.0, converged: np.ndarray | None = None) -> np.ndarray:
    """Eq. (11) with every chi evaluated as given; ``u`` (n, N) prime outputs.

    A plan of one coupling step (and ``rotation`` (N, N), sensor frame to reference
    frame, if given) for chi that are not a model's (the RBF baseline); a model
    decouples through :func:`exact` on its own plan.
    """
    k = np.asarray(k, dtype=float)
    terms = tuple(Term(c.output_axis, c.input_axis, c) for c in chis)
    cross = [t for t in terms if not t.own]
    fs = np.broadcast_to(np.asarray(full_scale_output, dtype=float), k.shape)
    steps: tuple = (Couple(k, (*cross, *(t for t in terms if t.own)), int(refine), fs),)
    if rotation is not None:
        steps += (Rotate(np.asarray(rotation, dtype=float)),)
    return exact(Plan(steps, len(k), len(k)), u, converged)


def settled(step: np.ndarray, step_tol) -> np.ndarray:
    """Rows (n,) whose last refinement step (n, N) is finite and within ``step_tol`` (N,)."""
    with np.errstate(invalid="ignore"):
        return np.all(np.abs(step) <= np.asarray(step_tol), axis=1)


def initial_forces(u: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Forces with no coupling correction, f_a = omega_a^-1(u_a) = u_a / k_aa (eq. 13 form).

    The "initial data" of Table 1: eq. (11) with every chi left out.
    """
    u = np.asarray(u, dtype=float)
    return u.reshape(-1, len(k)) / k


def usable(surrogate, full_scale_output: float = 1.0) -> bool:
    """Whether the table path may use a chi surrogate: present, and recorded within the gate.

    ``full_scale_output``: |k_a| F_FS,a of the chi's output a, in the data's units.
    """
    return surrogate is not None and surrogate.max_error <= MAX_SURROGATE_ERROR * full_scale_output
