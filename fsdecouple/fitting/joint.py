"""The coupling error model from calibration rows that load several components (issue 22).

The paper's sweeps load one component each (Section 3), so each chi_ab is trained
on the b sweeps alone (Section 2.3, step 3).  A real rig applies a moment as a
force on a lever arm: its moment rows load a force too, and no sweep isolates one
coupling function.  Eq. (11) rearranged is a model of every output,

    u_a = k_a f_a + sum_{b != a} chi_ab(u_b),                        (eq. 11)

additive in the outputs u_b, linear in the prime load (eq. 2).  A rig's readings
also bend with their *own* load (a factory-calibrated reading Fx that grows with
Fx^2), which a linear omega cannot hold.  The joint fit therefore extends eq. (4)'s
corrected coupling functions to b = a:

    u_a = k_a f_a + chi_aa(u_a) + sum_{b != a} chi_ab(u_b),          (eqs. 2, 4, 11)

chi_aa(u_a) being what is left of u_a beyond the straight line of eq. (2) along
its own load, as a function of the measured output, like every other chi.  So
decoupling stays eq. (11) with one more term, f_a = [u_a - chi_aa(u_a) - sum_b
chi_ab(u_b)] / k_a: no inversion of omega, and eq. (5)-(6)'s refinement iterates
the cross terms as before with chi_aa held at the measured u_a
(:func:`fsdecouple.core.decouple.decouple_exact`).

It is fitted for each output a by *backfitting*: start from its least-squares
linear form (the calibration matrix's), then in turn fit each chi_ab, chi_aa
included, as an epsilon-SVR (eq. 10) on the partial residual

    r_ab = u_a - k_a f_a - sum_{c != b} chi_ac(u_c)

as a function of u_b (eq. 4's training pairs, eq. 10's form), and k_a by least
squares through the origin on u_a - sum_b chi_ab(u_b) (eq. 2), until the chi stop
changing.  The SVRs keep Table 2's kernel width but not its C and epsilon, chosen
for the paper's repeated sweeps in volts: a rig file has one reading per load, and
C = 1000 with epsilon = 1e-4 F.S. follows each reading's noise; :func:`joint_svr`
sets C = JOINT_C and epsilon = the noise sigma.  On single-axis sweeps the partial
residual of a b-sweep row is its coupling error element e_ab (eq. 1) and the other
rows give chi_ab(0) = 0: the paper's training pairs; ``fit`` keeps the paper's own
path (Table 2, no chi_aa) for them, so their model is today's.  The model file
stores the chi_aa apart (``chi_own``, format version 4).

The loads must be separable: two loads that move together in every row (a lever
arm with no pure-force sweep) leave k_a and chi_ab confounded, and are refused by
name (:func:`check_separable`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..errors import InputError

ITERATIONS = 2  # backfitting sweeps at most: on lever-arm rigs the residual stops falling after one
# Stop when no chi moved by more than this fraction of its output's full scale in
# one sweep: the SVRs' epsilon of Table 2 (1e-4) is the smallest change they resolve.
CONVERGED = 1e-4
# The joint fit's SVR penalty C in full-scale units (joint_svr): a chi is a few % of
# F.S., so C = 1 still lets it reach any shape the calibration resolves, while Table
# 2's C = 1000 (for volts and the paper's repeated sweeps) follows single readings' noise.
JOINT_C = 1.0
# Singular values of the normalised load design below this fraction of the largest
# mean loads that no row separates (a double's rounding of full-scale loads is 1e-16).
SEPARABLE = 1e-6


def joint_svr(svr, f: np.ndarray, u: np.ndarray, a: int, sigma: float | None = None):
    """Table 2's SVR settings as the joint fit of output ``a`` uses them (normalised units).

    C is JOINT_C, and epsilon the noise sigma of output a (at least Table 2's): ``sigma``
    when the samples of a pose log measured it (data/poses.py), else the residual scatter
    of a least-squares pilot fit of u_a, quadratic in every load, sigma^2 = RSS / (n - p).
    An epsilon-tube as wide as the noise (Cherkassky and Ma, 2004) and a C that bounds a
    chi's coefficients keep the SVRs from following the noise of single readings, which a
    rig file of one reading per load is made of.
    """
    if sigma is not None and np.isfinite(sigma):
        return replace(svr, C=JOINT_C, epsilon=max(svr.epsilon, float(sigma)))
    design = np.column_stack([f, f ** 2])
    coef, *_ = np.linalg.lstsq(design, u[:, a], rcond=None)
    dof = len(u) - np.linalg.matrix_rank(design)
    sigma = float(np.sqrt(((u[:, a] - design @ coef) ** 2).sum() / dof)) if dof > 0 else 0.0
    return replace(svr, C=JOINT_C, epsilon=max(svr.epsilon, sigma))


def multi_load(forces: np.ndarray) -> bool:
    """Whether any calibration row loads more than one component."""
    return bool(((np.asarray(forces) != 0.0).sum(axis=1) > 1).any())


def check_separable(forces: np.ndarray, full_scale, loads, source: str) -> None:
    """Refuse loads the rows cannot tell apart (a rank-deficient design), by name.

    Also refuses a component loaded at fewer than two distinct non-zero levels: eq. (2)
    and a chi need more than one loaded point to be fitted.
    """
    s = np.asarray(forces, dtype=float) / np.asarray(full_scale, dtype=float)
    for a, name in enumerate(loads):
        levels = np.unique(s[s[:, a] != 0.0, a])
        if levels.size < 2:
            raise InputError(f"{source}: {name} is loaded at {levels.size} distinct non-zero "
                             f"level{'s' if levels.size != 1 else ''}; fitting needs at least 2")
    _, sv, vt = np.linalg.svd(s, full_matrices=False)
    if sv[-1] < SEPARABLE * sv[0]:
        v = vt[-1]
        tied = [loads[a] for a in np.flatnonzero(np.abs(v) > 0.1 * np.abs(v).max())]
        raise InputError(f"{source}: loads {' and '.join(tied)} move together in every row "
                         "(a rank-deficient design): the rows cannot separate them; add rows "
                         f"that load {tied[0]} without {tied[1]}")


def backfit(f: np.ndarray, u: np.ndarray, a: int, fit_chi, *, iterations: int = ITERATIONS,
            converged: float = CONVERGED, own: bool = False) -> tuple[float, dict[int, object]]:
    """k_a and the chi_ab of output ``a`` by backfitting, in normalised units.

    Parameters
    ----------
    f : ndarray, shape (n, N)
        Loads as fractions of full scale.
    u : ndarray, shape (n, N)
        Zero-corrected outputs as fractions of their full-scale output.
    a : int
        The output modelled.
    fit_chi : callable
        ``fit_chi(x, y)`` -> a callable chi (an epsilon-SVR of eq. 10) of x.
    own : bool
        Fit the own-load chi_aa(u_a) too (module docstring).

    Returns
    -------
    k : float
        Slope of eq. (2) in normalised units.
    chi : dict
        One fitted chi per input b != a, and for b = a with ``own``.
    """
    n = u.shape[1]
    others = [b for b in range(n) if b != a]
    design = np.column_stack([f[:, a], u[:, others]])
    coef, *_ = np.linalg.lstsq(design, u[:, a], rcond=None)
    k = float(coef[0])
    part = {b: coef[j + 1] * u[:, b] for j, b in enumerate(others)}  # chi_ab(u_b), linear start
    terms = [*others, a] if own else others
    if own:
        part[a] = np.zeros(len(u))
    chi: dict[int, object] = {}
    for _ in range(iterations):
        moved = 0.0
        for b in terms:
            r = u[:, a] - k * f[:, a] - sum(part[c] for c in terms if c != b)
            chi[b] = fit_chi(u[:, b], r)
            new = chi[b](u[:, b])
            moved = max(moved, float(np.abs(new - part[b]).max()))
            part[b] = new
        y = u[:, a] - sum(part.values())
        k = float(f[:, a] @ y / (f[:, a] @ f[:, a]))
        if moved <= converged:
            break
    return k, chi
