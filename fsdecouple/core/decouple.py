"""Eq. (11), once, over (n, N) arrays: the exact path and the table path.

    f_a = omega_a^-1 [u_a - sum_{b != a} chi_ab(u_b)]                    eq. (11)

with omega_a^-1(v) = v / k_aa (eq. 13 form).  N is the number of components
(len(k)); nothing here knows their names.  A joint fit of rig rows may add an own-load
chi_aa(u_a) (:mod:`fsdecouple.fitting.joint`): it is subtracted like the others, always at
the measured u_a (it models the outputs as measured), on every path; its table shares
input a's grid, h_a = -chi_aa / k_a added to u_a / k_a before the cross terms.

* :func:`decouple_exact` evaluates every chi as given (the SVR's kernel sum, or
  any other callable such as the RBF baseline's networks);
* :class:`TableDecoupler` evaluates the same sum from the chi surrogates
  (:mod:`fsdecouple.core.surrogate`) at memory speed, compiled
  (:mod:`fsdecouple.core.table_kernel`) and on every core, and hands rows outside the
  tables (or with a NaN) to the exact path.  Eq. (11) is a sum of one-variable
  functions, ``f_a = u_a / k_a + sum_{b != a} g_ab(u_b)`` with g_ab = -chi_ab / k_a,
  and the N - 1 chi fed by input b share one grid, so one table index per input
  serves them all.
* :meth:`TableDecoupler.one` is the same table arithmetic for one vector in plain
  Python, generated for N from the template below and tested bit for bit
  against the array path.

Second-order refinement (``refine = K``; README, "Second-order refinement"):
eq. (11) evaluated at estimates p of the prime outputs instead of u (eq. 5-6),

    p^0 = u,   p_b^(j+1) = u_b - sum_{c != b} chi_bc(p_c^j)   (j = 0 .. K - 1)
    f_a = [u_a - sum_{b != a} chi_ab(p_b^K)] / k_aa,  so k_a f_a = p_a^(K+1).

A joint fit's own-load chi_aa (fitting/joint.py) is subtracted from u_a before these
steps, at the measured u_a: p^(j+1) = u - chi_own(u) - sum chi(p^j).
A contraction when (N - 1) max|chi'| < 1.  K = 0 is eq. (11), bit for bit, on
every path.  A row whose last step k f - p^K is not finite or above
REFINE_TOLERANCE F.S. gets NaN forces and converged = False, never silent forces.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from typing import Protocol

import numpy as np

# The table path promises forces within PROMISE of the exact kernel sum, as a
# fraction of each output's full scale |k_a| F_FS,a (so 1e-9 V on the paper's sensor,
# whose full-scale outputs are about 1 V, and the same fraction in mV or counts).
# An output adds N - 1 chi, and a surrogate's recorded max_error is the largest
# error found on its check grid, which at the kernel sum's own rounding noise can
# be exceeded a little between check points.  So a surrogate is used only if its
# recorded error is at most a quarter of the promise (fit builds them to a tenth).
PROMISE = 1e-9
MAX_SURROGATE_ERROR = PROMISE / 4
# Up to this many rows, a call goes row by row through the plain-Python evaluator
# (~1 us a row, bit-identical) rather than the compiled block path, whose numba
# import (0.3 s, with scipy) a control loop need not pay.
SMALL_ROWS = 32
BLOCK_ROWS = 1 << 15  # rows a task of the thread pool compiles through at a time
# A refined row has settled when its last step, k_a f_a - p_a^K, is at most this
# fraction of each full-scale output.  Under Section 2.1's assumptions it is at most
# (N - 1) 0.05 * 5 % = 0.5 % F.S. at K = 1 (N = 3), tenfold less a step on; above 1 %
# the row is outside the regime known to contract: diverging, not just slow.
REFINE_TOLERANCE = 0.01


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


def decouple_exact(u: np.ndarray, k: np.ndarray, chis: Iterable[ChiFunction],
                   rotation: np.ndarray | None = None, *, refine: int = 0,
                   full_scale_output=1.0, converged: np.ndarray | None = None) -> np.ndarray:
    """Eq. (11) with every chi evaluated as given; ``u`` (n, N) zero-corrected outputs.

    ``rotation`` (N, N), if given, takes the forces from the sensor frame to the
    reference frame (end of Section 2.3).  ``refine``: K fixed-point steps on the
    prime outputs first (module docstring); rows that do not settle within
    ``REFINE_TOLERANCE`` of ``full_scale_output`` (N,) get NaN forces and False in
    ``converged`` (n,), if given.  K = 0 is eq. (11) as written, every row converged.
    """
    chis = list(chis)
    own = [c for c in chis if c.output_axis == c.input_axis]  # chi_aa of a joint fit (joint.py)
    chis = [c for c in chis if c.output_axis != c.input_axis]
    base = u - coupling_errors(u, own) if own else u  # the own-load chi always at the measured u_a
    p = u
    for _ in range(refine):
        p = base - coupling_errors(p, chis)
    kf = base - coupling_errors(p, chis)  # = p^(K+1)
    f = kf / k
    ok = settled(kf - p, full_scale_output) if refine else np.ones(len(f), dtype=bool)
    f[~ok] = np.nan
    if rotation is not None:
        f = f @ np.asarray(rotation).T
    if converged is not None:
        converged[:] = ok
    return f


def settled(step: np.ndarray, full_scale_output) -> np.ndarray:
    """Rows (n,) whose last refinement step (n, N) is finite and within REFINE_TOLERANCE F.S."""
    with np.errstate(invalid="ignore"):
        return np.all(np.abs(step) <= REFINE_TOLERANCE * np.asarray(full_scale_output), axis=1)


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


def _fed_order(n: int, b: int) -> list[int]:
    """Outputs fed by input b, in table-column order: (b + 1 + m) % n for m = 0 .. n - 2."""
    return [(b + 1 + m) % n for m in range(n - 1)]


def _sum_order(n: int, a: int) -> list[tuple[int, int]]:
    """(input b, table column m) added into output a, in order: b = a - 1, a - 2, ... (mod n).

    The order is fixed (it sets the last bit of every force); for three axes it
    is f_x = u_x / k_x + g_xz + g_xy, as the path has always summed.
    """
    return [((a - d) % n, (a - ((a - d) % n) - 1) % n) for d in range(1, n)]


_pool: ThreadPoolExecutor | None = None
_pool_lock = threading.Lock()


def default_workers() -> int:
    return os.cpu_count() or 1


def _executor() -> ThreadPoolExecutor:
    global _pool
    with _pool_lock:
        if _pool is None:
            _pool = ThreadPoolExecutor(default_workers(), thread_name_prefix="fsdecouple")
        return _pool


class TableDecoupler:
    """Eq. (11) from the chi surrogates; the exact path outside their intervals.

    Parameters
    ----------
    k : ndarray, shape (N,)
        Slopes k_aa of eq. (2).
    surrogates : mapping of (a, b) to ChiSurrogate
        The table of every chi_ab; the N - 1 tables of one input b share a grid.  With
        an own-load chi_aa of a joint fit, (a, a) too, on input a's grid (every a or none).
    exact : callable
        ``exact(u, rotate, refine, converged) -> f`` for rows the tables do not
        cover (:func:`decouple_exact` with the same K).
    rotation : ndarray, shape (N, N), optional
        Sensor frame to reference frame.
    full_scale_output : ndarray, shape (N,), optional
        |k_a| F_FS,a, to which the refinement's settled test is relative.

    Build with :meth:`from_chis`, which returns None when a table is missing or
    unusable (then every row takes the exact path).
    """

    def __init__(self, k: np.ndarray, surrogates: dict[tuple[int, int], object],
                 exact: Callable[..., np.ndarray], rotation=None, full_scale_output=None):
        n = len(k)
        self.n = n
        self._exact = exact
        self._small: dict[int, Callable] = {}
        self.k = np.asarray(k, dtype=float)
        self.inv_k = 1.0 / self.k
        self.step_tol = REFINE_TOLERANCE * (np.ones(n) if full_scale_output is None
                                            else np.asarray(full_scale_output, dtype=float))
        self.rotation = None if rotation is None else np.asarray(rotation, dtype=float)
        lo, inv, count = [], [], []
        coefs = []  # [b][m]: (intervals_b, 4), c0..c3 of g_ab for the m-th output fed by b
        self.rows: list[list[tuple[float, ...]]] = []  # per input, for the one-vector path
        for b in range(n):
            fed = [surrogates[(a, b)] for a in _fed_order(n, b)]
            coef = [s.coefficients() * -self.inv_k[a] for a, s in zip(_fed_order(n, b), fed,
                                                                        strict=True)]
            coefs.append([c.T for c in coef])
            lo.append(fed[0].lo)
            inv.append(fed[0].inv_step)
            count.append(fed[0].intervals)
            self.rows.append([tuple(r) for r in np.concatenate(coef).T.tolist()])
        self.tab = np.zeros((n, n - 1, max(count), 4))  # for table_kernel.eq11_rows
        for b, per_input in enumerate(coefs):
            for m, c in enumerate(per_input):
                self.tab[b, m, :len(c)] = c
        # own-load chi_aa (joint.py): h_a = -chi_aa / k_a on input a's grid, at the measured u_a
        self.has_own = (0, 0) in surrogates
        self.own = np.zeros((n, max(count), 4))
        self.own_rows: list[list[tuple[float, ...]]] = [[] for _ in range(n)]
        if self.has_own:
            for a in range(n):
                c = surrogates[(a, a)].coefficients() * -self.inv_k[a]
                self.own[a, :c.shape[1]] = c.T
                self.own_rows[a] = [tuple(r) for r in c.T.tolist()]
        self.lo = np.array(lo)
        self.inv_step = np.array(inv)
        self.intervals = np.array(count, dtype=float)
        sums = [_sum_order(n, a) for a in range(n)]
        self.sum_b = np.array([[b for b, _ in terms] for terms in sums], dtype=np.intp).reshape(n, n - 1)
        self.sum_m = np.array([[m for _, m in terms] for terms in sums], dtype=np.intp).reshape(n, n - 1)

    @classmethod
    def from_chis(cls, k, chis: Iterable, exact, rotation=None, full_scale_output=None
                  ) -> TableDecoupler | None:
        """From chi objects with ``output_axis``, ``input_axis`` and ``surrogate``.

        ``full_scale_output`` (N,): |k_a| F_FS,a, to which the gate is relative.  Own-load
        chi_aa (output = input) are given for every a or for none.
        """
        tables = {(c.output_axis, c.input_axis): c.surrogate for c in chis}
        n = len(k)
        u_fs = np.ones(n) if full_scale_output is None else np.asarray(full_scale_output, float)
        own = sum((a, a) in tables for a in range(n))
        if own not in (0, n):
            return None
        for b in range(n):
            feeds = [a for a in range(n) if a != b or own]  # the own chi_bb shares b's grid
            fed = [tables.get((a, b)) for a in feeds]
            if not all(usable(tables.get((a, b)), u_fs[a]) for a in feeds):
                return None
            if len({(s.lo, s.hi, s.intervals) for s in fed}) != 1:
                return None  # the evaluator shares one index per input
        return cls(k, tables, exact, rotation, full_scale_output)

    # --- arrays -------------------------------------------------------------------

    def _block(self, u: np.ndarray, out: np.ndarray, rotate: bool, covered, refine: int = 0,
               converged=None) -> None:
        from .table_kernel import eq11_rows  # numba (and scipy) only once arrays are decoupled

        inside, settled = np.empty(len(u), dtype=bool), np.empty(len(u), dtype=bool)
        eq11_rows(u, self.lo, self.inv_step, self.intervals, self.inv_k, self.k, self.step_tol,
                  self.tab, self.sum_b, self.sum_m, int(refine), self.own, self.has_own, out,
                  inside, settled)
        if rotate and self.rotation is not None:
            out[:] = out @ self.rotation.T
        if converged is not None:
            converged[:] = settled
        if not inside.all():  # outside a table (at u or at a step), or NaN: the exact path
            bad = ~inside
            sub = None if converged is None else np.ones(int(bad.sum()), dtype=bool)
            out[bad] = self._exact(u[bad], rotate, refine, sub)
            if covered is not None:
                covered[bad] = False
            if converged is not None:
                converged[bad] = sub

    def decouple(self, u: np.ndarray, *, rotate: bool = True, workers: int | None = None,
                 block_rows: int | None = None, covered: np.ndarray | None = None,
                 refine: int = 0, converged: np.ndarray | None = None) -> np.ndarray:
        """Forces by eq. (11) for zero-corrected outputs ``u``, shape (n, N).

        ``covered``, a boolean array of n rows, is set False where a row left the
        tables (outside their intervals, or NaN, at u or at any refinement step)
        and took the exact path.  ``refine``: K fixed-point steps (module docstring);
        ``converged`` (n,), if given, is set False where a row did not settle (NaN forces).
        """
        if int(refine) != refine or refine < 0:  # the CLI and config refuse these first
            raise ValueError(f"refine: K = {refine!r}; expected a whole number >= 0")
        u = np.ascontiguousarray(u, dtype=float).reshape(-1, self.n)
        if covered is not None:
            covered[:] = True
        if u.shape[0] <= SMALL_ROWS and covered is None and converged is None and (
                not rotate or self.rotation is None):
            if refine not in self._small:
                self._small[refine] = self.one(rotate=False, refine=refine)
            one = self._small[refine]
            return np.array([one(*v) for v in u.tolist()], dtype=float).reshape(-1, self.n)
        out = np.empty_like(u)
        block_rows = block_rows or BLOCK_ROWS
        starts = range(0, u.shape[0], block_rows)
        workers = default_workers() if workers is None else workers

        def part(mask, a):
            return None if mask is None else mask[a:a + block_rows]

        def run_blocks(chunk) -> None:
            for a in chunk:
                self._block(u[a:a + block_rows], out[a:a + block_rows], rotate,
                            part(covered, a), refine, part(converged, a))

        if workers <= 1 or len(starts) <= 1:
            run_blocks(starts)
            return out
        # contiguous stripes, one task per stripe of blocks, so a thread keeps its
        # cache and the pool sees few submissions
        per = -(-len(starts) // min(len(starts), 4 * workers))
        stripes = [starts[k:k + per] for k in range(0, len(starts), per)]
        pool = _executor() if workers == default_workers() else ThreadPoolExecutor(workers)
        try:
            list(pool.map(run_blocks, stripes))
        finally:
            if pool is not _pool:
                pool.shutdown()
        return out

    # --- one vector -----------------------------------------------------------------

    def one(self, rotate: bool = True, refine: int = 0) -> Callable[..., tuple[float, ...]]:
        """A plain-Python function ``(u_1, ..., u_N) -> (f_1, ..., f_N)``, no numpy per call.

        Generated for N from :func:`one_vector_source`: the array path's
        arithmetic in the same order (bit-identical without a rotation; the
        rotation is summed in Python, not by BLAS).  ``refine``: K fixed-point
        steps, as :meth:`decouple`; a row that does not settle gives NaN forces.
        """
        rot = None if self.rotation is None or not rotate else \
            [tuple(map(float, r)) for r in self.rotation]
        own = self.own_rows if self.has_own else None
        exact = self._exact
        env = {
            "rows": self.rows, "lo": [float(v) for v in self.lo],
            "inv": [float(v) for v in self.inv_step], "cnt": [float(v) for v in self.intervals],
            "ik": [float(v) for v in self.inv_k], "rot": rot,
            "exact": lambda *u: exact(np.array([u], dtype=float), False, refine)[0].tolist(),
            "kk": [float(v) for v in self.k], "tol": [float(v) for v in self.step_tol],
            "refine": int(refine), "nan": float("nan"),
        }
        if own is not None:
            env["own"] = own
        namespace: dict = {}
        exec(compile(one_vector_source(self.n, rot is not None, own is not None),
                     "<fsdecouple.core.decouple.one>", "exec"), namespace)
        return namespace["make"](**env)


def one_vector_source(n: int, rotate: bool, own: bool = False) -> str:
    """Python source of the one-vector evaluator of :meth:`TableDecoupler.one` for N = n.

    The statements follow :meth:`TableDecoupler._block` step by step: the table
    index ``t = (x_b - lo_b) * inv_step_b``, a Horner step per chi, then
    ``f_a = u_a / k_a + sum g_ab`` in :func:`_sum_order`.  ``make`` returns
    ``decouple_one`` (x = u) for ``refine == 0``, else ``decouple_refined`` (x = p
    after ``refine`` steps p_a = k_a f_a, then the settled test).  With ``own``, the
    own-load terms h_a = -chi_aa(u_a) / k_a at the measured u, first, from ``own[a]``.
    """
    u, p, f = ([f"{c}{b}" for b in range(n)] for c in "upf")
    inside = " and ".join(f"0.0 <= t{b} < n{b}" for b in range(n))
    lines = ["def make(rows, lo, inv, cnt, ik, rot, exact, kk, tol, refine, nan"
             + (", own):" if own else "):")]
    for b in range(n):
        lines += [f"    r{b}, l{b}, i{b}, n{b}, k{b} = rows[{b}], lo[{b}], inv[{b}], cnt[{b}], ik[{b}]",
                  f"    K{b}, s{b} = kk[{b}], tol[{b}]"]
        if own:
            lines.append(f"    o{b} = own[{b}]")
    if rotate:
        lines.append(f"    ({', '.join(f'R{a}' for a in range(n))},) = rot")

    def index(x: list[str], pad: str) -> list[str]:
        return [f"{pad}t{b} = ({x[b]} - l{b}) * i{b}" for b in range(n)]

    def forces(pad: str, into: list[str], k: str = "") -> list[str]:  # g_ab at t_b, then sums
        out = []
        for b in range(n):
            coef = [f"c{m}_{j}" for m in range(n - 1) for j in range(4)]
            out += [f"{pad}i = int(t{b})", f"{pad}s = t{b} - i", f"{pad}{', '.join(coef)} = r{b}[i]"]
            out += [f"{pad}g{b}_{m} = ((c{m}_3 * s + c{m}_2) * s + c{m}_1) * s + c{m}_0"
                    for m in range(n - 1)]
        sums = [f"{u[a]} * k{a}" + (f" + h{a}" if own else "")
                + "".join(f" + g{b}_{m}" for b, m in _sum_order(n, a)) for a in range(n)]
        return out + [f"{pad}{into[a]} = ({sums[a]}) * K{a}" if k else f"{pad}{into[a]} = {sums[a]}"
                      for a in range(n)]

    def own_terms(pad: str) -> list[str]:  # h_a at t_a of the measured u (index(u) before)
        if not own:
            return []
        out = [f"{pad}if {inside}:"]
        for a in range(n):
            out += [f"{pad}    i = int(t{a})", f"{pad}    s = t{a} - i",
                    f"{pad}    c0, c1, c2, c3 = o{a}[i]",
                    f"{pad}    h{a} = ((c3 * s + c2) * s + c1) * s + c0"]
        return out + [f"{pad}else:  # fails the test at u below: the exact path",
                      f"{pad}    {' = '.join(f'h{a}' for a in range(n))} = nan"]

    rows = [" + ".join(f"R{a}[{b}] * {f[b]}" for b in range(n)) for a in range(n)]
    tail = ["        else:  # outside a table (at u or at a step), or NaN: the exact path",
            f"            {', '.join(f)}, = exact({', '.join(u)})",
            f"        return ({', '.join(rows if rotate else f)},)"]
    # eq. (11) at u
    lines += [f"    def decouple_one({', '.join(u)}):", *index(u, "        "),
              *own_terms("        "), f"        if {inside}:", *forces("            ", f), *tail]
    # eq. (11) at p, after `refine` steps p_a <- k_a f_a (as TableDecoupler._block)
    settled = " and ".join(f"abs(f{a} * K{a} - p{a}) <= s{a}" for a in range(n))
    lines += [f"    def decouple_refined({', '.join(u)}):",
              *(index(u, "        ") + own_terms("        ") if own else []),
              f"        {', '.join(p)} = {', '.join(u)}",
              "        for _ in range(refine):", *index(p, "            "),
              f"            if not ({inside}):", "                break  # t fails again below",
              *forces("            ", p, "K"), "        else:", *index(p, "            "),
              f"        if {inside}:", *forces("            ", f),
              f"            if not ({settled}):",
              f"                {' = '.join(f)} = nan  # did not settle: no silent forces", *tail,
              "    return decouple_refined if refine else decouple_one"]
    return "\n".join(lines) + "\n"
