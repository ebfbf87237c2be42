"""The table path of a decoupling plan: eq. (11) from the chi tables, at memory speed.

Eq. (11) is a sum of one-variable functions, ``f_a = u_a / k_a + h_a(u_a) + sum_{b != a}
g_ab(p_b)`` with g_ab = -chi_ab / k_a and h_a = -chi_aa / k_a (an own-load chi of a joint
fit, at the measured u_a), and the chi fed by input b share one grid, so one table index
per input serves them all (:func:`fsdecouple.core.surrogate.cell`; each g a
:func:`~fsdecouple.core.surrogate.horner` step).  :class:`TableDecoupler` reads the
tables of a plan's :class:`~fsdecouple.core.plan.Couple` step into arrays and
evaluates the plan (:func:`~fsdecouple.core.plan.walk`) with them, in three forms
that give the same bits:

* numpy over blocks of rows (:func:`eq11_rows`), on every core;
* the compiled kernel (:mod:`fsdecouple.core.table_kernel`, numba) for calls of
  COMPILED_WORK chi evaluations or more (``compiled``): loading numba and the cached
  kernel costs ~0.45 s, which a control loop or a model load need not pay;
* one vector in plain Python (:meth:`TableDecoupler.one`, a closure over lists).

Rows outside a table (at u or at a refinement step) or holding a NaN go back to the
exact path (:func:`fsdecouple.core.decouple.couple`) on the same prime outputs.
"""

from __future__ import annotations

import math
import os
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from operator import mul

import numpy as np

from .decouple import couple, usable
from .plan import (
    Couple,
    InputCorrection,
    Linear,
    Plan,
    Project,
    Rotate,
    TemperatureCorrection,
    UnknownStep,
    walk,
)
from .surrogate import cell, horner

# Up to this many rows, a call goes row by row through the plain-Python evaluator
# (~3 us a row, bit-identical) rather than numpy's ~60 calls per block.
SMALL_ROWS = 32
# From this many chi evaluations a call uses the compiled kernel (TableDecoupler.work:
# rows x (K + 1) steps x N (N - 1), plus N own-load chi once), 2.8 M rows of 3 axes or
# 560,000 of six at K = 0.  On six axes numpy decouples 5-6 M rows/s of a million, the
# kernel 12-14 (docs/benchmarks.md); on three axes the two are closer (row 1d, 10 M
# rows: numpy took 0.86-1.97x the kernel's time in four runs).  Loading numba and the
# cached kernel takes ~0.45 s of a fresh process: a call that numpy does in ~0.1 s or
# more is one of many (a notebook's arrays, a log in parts), and the kernel's steady
# speed is what counts; a shorter one, a model load and a control loop never load it.
# ``apply`` decides for a whole log instead (logs/apply.py APPLY_COMPILED_WORK).
COMPILED_WORK = 1 << 24
# Rows a task of the thread pool goes through at a time.  Each block costs some forty
# numpy calls whose Python between them holds the GIL, so with two threads larger
# blocks wait less: on 1 M rows, 2 threads, median of 9, 1 << 16 against 1 << 15 took
# 39.5 against 44.2 ms (3 axes, K = 0), 166 against 194 (K = 3), 173 against 225 (six
# axes) and 655 against 817 (six, K = 3); 1 << 17 was no better.  Same bits.
BLOCK_ROWS = 1 << 16


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


def eq11_rows(u, lo, inv_step, intervals, inv_k, k, step_tol, tab, sum_b, sum_m, refine, own,
              has_own, out, inside, settled) -> None:
    """:func:`fsdecouple.core.table_kernel.eq11_rows` in numpy, operation for operation.

    Rows that leave a table at some step are marked in ``inside`` and computed on with
    interval 0, for the exact path to overwrite.
    """
    with np.errstate(all="ignore"):  # rows outside a table compute on at interval 0
        _eq11_rows(u, lo, inv_step, intervals, inv_k, k, step_tol, tab, sum_b, sum_m, refine,
                   own, has_own, out, inside, settled)


def _eq11_rows(u, lo, inv_step, intervals, inv_k, k, step_tol, tab, sum_b, sum_m, refine, own,
               has_own, out, inside, settled) -> None:
    dim = u.shape[1]
    x = u
    ok = np.ones(len(u), dtype=bool)
    for step in range(refine + 1):
        cells = [cell(x[:, b], lo[b], inv_step[b], intervals[b]) for b in range(dim)]
        for _, _, inside_b in cells:
            ok &= inside_b
        if step == 0:  # x = u: u_a / k_a, and the own-load term at the measured u_a
            base = [u[:, a] * inv_k[a] for a in range(dim)]
            if has_own:
                for a in range(dim):
                    i, s, _ = cells[a]
                    base[a] += horner(*(own[a, :, j].take(i) for j in range(4)), s)
        f = np.empty_like(u)
        for a in range(dim):
            fa = base[a].copy()
            for d in range(dim - 1):
                b, m = sum_b[a, d], sum_m[a, d]
                i, s, _ = cells[b]
                fa += horner(*(tab[b, m, :, j].take(i) for j in range(4)), s)
            f[:, a] = fa
        if step < refine:
            x = f * k  # p^(j+1) = k f
    done = np.ones(len(u), dtype=bool)
    if refine > 0:
        with np.errstate(invalid="ignore"):
            done = np.all(np.abs(f * k - x) <= step_tol, axis=1) | ~ok
    f[~done] = np.nan
    out[:] = f
    inside[:] = ok
    settled[:] = done


class TableDecoupler:
    """A plan's forces from its chi tables; the exact path outside them.

    Build with :meth:`from_plan`, which returns None when a table is missing or
    unusable (then every row takes the exact path).  ``plan``: a model's plan
    (:func:`fsdecouple.core.plan.model_plan`), the tables those of its terms; an
    own-load chi_aa (joint fit) on input a's grid, for every a or none.
    """

    def __init__(self, plan: Plan):
        self.plan = plan
        step = plan.couple
        self.step = step
        n = len(step.k)
        self.n = n
        tables = {(t.out, t.inp): t.table for t in step.terms}
        self._small: dict[int, Callable] = {}
        self._plans: dict[tuple[bool, int], Plan] = {}
        self.k = np.asarray(step.k, dtype=float)
        self.inv_k = 1.0 / self.k
        self.step_tol = np.asarray(step.step_tol, dtype=float)
        lo, inv, count = [], [], []
        coefs = []  # [b][m]: (intervals_b, 4), c0..c3 of g_ab for the m-th output fed by b
        self.rows: list[list[tuple[float, ...]]] = []  # per input, for the one-vector path
        for b in range(n):
            fed = [tables[(a, b)] for a in _fed_order(n, b)]
            coef = [s.coefficients() * -self.inv_k[a] for a, s in zip(_fed_order(n, b), fed,
                                                                        strict=True)]
            coefs.append([c.T for c in coef])
            lo.append(fed[0].lo)
            inv.append(fed[0].inv_step)
            count.append(fed[0].intervals)
            self.rows.append([tuple(r) for r in np.concatenate(coef).T.tolist()])
        self.tab = np.zeros((n, n - 1, max(count), 4))
        for b, per_input in enumerate(coefs):
            for m, c in enumerate(per_input):
                self.tab[b, m, :len(c)] = c
        # own-load chi_aa (joint.py): h_a = -chi_aa / k_a on input a's grid, at the measured u_a
        self.has_own = (0, 0) in tables
        self.own = np.zeros((n, max(count), 4))
        self.own_rows: list[list[tuple[float, ...]]] = [[] for _ in range(n)]
        if self.has_own:
            for a in range(n):
                c = tables[(a, a)].coefficients() * -self.inv_k[a]
                self.own[a, :c.shape[1]] = c.T
                self.own_rows[a] = [tuple(r) for r in c.T.tolist()]
        self.lo = np.array(lo)
        self.inv_step = np.array(inv)
        self.intervals = np.array(count, dtype=float)
        sums = [_sum_order(n, a) for a in range(n)]
        self.sum_b = np.array([[b for b, _ in terms] for terms in sums], dtype=np.intp).reshape(n, n - 1)
        self.sum_m = np.array([[m for _, m in terms] for terms in sums], dtype=np.intp).reshape(n, n - 1)

    def work(self, rows: float, refine: int) -> float:
        """Chi evaluations of ``rows`` rows at K = ``refine``: N (N - 1) a step, K + 1 steps,
        and the N own-load chi once (at the measured u)."""
        n = self.n
        return rows * ((int(refine) + 1) * n * (n - 1) + (n if self.has_own else 0))

    @classmethod
    def from_plan(cls, plan: Plan) -> TableDecoupler | None:
        """None unless every chi has a usable table (decouple.usable, relative to its
        output's full scale) and the tables of one input share one grid."""
        step = plan.couple
        if step is None:
            return None
        tables = {(t.out, t.inp): t.table for t in step.terms}
        n = len(step.k)
        u_fs = np.ones(n) if step.full_scale_output is None else step.full_scale_output
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
        return cls(plan)

    def _plan(self, rotate: bool, refine: int, before: tuple = ()) -> Plan:
        """The plan without its rotation (``rotate`` False) and with K = ``refine``; ``before``:
        steps on the raw inputs first (a temperature model's correction and zero)."""
        key = (bool(rotate), int(refine))
        if key not in self._plans:
            steps = tuple(replace(s, refine=int(refine)) if isinstance(s, Couple) else s
                          for s in self.plan.steps if rotate or not isinstance(s, Rotate))
            self._plans[key] = replace(self.plan, steps=steps)
        plan = self._plans[key]
        if not before:
            return plan
        return replace(plan, steps=(*before, *plan.steps), n_outputs=before[0].n_inputs)

    # --- arrays -------------------------------------------------------------------

    def _block(self, u, out, covered, converged, compiled: bool, refine: int) -> None:
        if compiled:
            from .table_kernel import eq11_rows as kernel  # numba (and scipy): large calls only
        else:
            kernel = eq11_rows
        inside, ok = np.empty(len(u), dtype=bool), np.empty(len(u), dtype=bool)
        kernel(u, self.lo, self.inv_step, self.intervals, self.inv_k, self.k, self.step_tol,
               self.tab, self.sum_b, self.sum_m, refine, self.own, self.has_own, out,
               inside, ok)
        if not inside.all():  # outside a table (at u or at a step), or NaN: the exact path
            bad = ~inside
            f, ok[bad] = couple(replace(self.step, refine=refine), u[bad])
            f[~ok[bad]] = np.nan
            out[bad] = f
            if covered is not None:
                covered[bad] = False
        if converged is not None:
            converged[:] = ok

    def _couple(self, u, workers, block_rows, covered, converged, compiled, refine) -> np.ndarray:
        u = np.ascontiguousarray(u, dtype=float)
        out = np.empty_like(u)
        starts = range(0, u.shape[0], block_rows)

        def part(mask, a):
            return None if mask is None else mask[a:a + block_rows]

        def run_blocks(chunk) -> None:
            for a in chunk:
                self._block(u[a:a + block_rows], out[a:a + block_rows], part(covered, a),
                            part(converged, a), compiled, refine)

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

    def decouple(self, u: np.ndarray, *, rotate: bool = True, workers: int | None = None,
                 block_rows: int | None = None, covered: np.ndarray | None = None,
                 refine: int | None = None, converged: np.ndarray | None = None,
                 compiled: bool | None = None, before: tuple = ()) -> np.ndarray:
        """Forces of the plan for raw outputs ``u``, shape (n, M).

        ``covered``, a boolean array of n rows, is set False where a row left the
        tables (outside their intervals, or NaN, at u or at any refinement step)
        and took the exact path.  ``refine``: K fixed-point steps (default the
        plan's); ``converged`` (n,), if given, is set False where a row did not
        settle (NaN forces).  ``compiled``: use the numba kernel (default: from
        COMPILED_WORK chi evaluations; numpy without numba installed).  ``before``: steps on the raw
        inputs ahead of the plan's own (a :class:`~fsdecouple.core.plan.TemperatureCorrection`).
        """
        refine = self.step.refine if refine is None else refine
        if int(refine) != refine or refine < 0:  # the CLI and config refuse these first
            raise ValueError(f"refine: K = {refine!r}; expected a whole number >= 0")
        plan = self._plan(rotate, refine, before)
        u = np.asarray(u, dtype=float).reshape(-1, plan.n_outputs)
        if covered is not None:
            covered[:] = True
        if compiled is None:
            compiled = self.work(u.shape[0], refine) >= COMPILED_WORK
        if compiled and not _numba_available():
            compiled = False
        workers = default_workers() if workers is None else workers
        block_rows = block_rows or BLOCK_ROWS
        refine = int(refine)

        def couple_step(_step: Couple, x: np.ndarray) -> np.ndarray:
            if len(x) <= SMALL_ROWS and covered is None and converged is None:
                if refine not in self._small:
                    self._small[refine] = self._one_couple(replace(self.step, refine=refine))
                one = self._small[refine]
                return np.array([one(v) for v in x.tolist()], dtype=float).reshape(-1, self.n)
            return self._couple(x, workers, block_rows, covered, converged, compiled, refine)

        return walk(plan, u, couple_step, evaluator="the table path")

    # --- one vector -----------------------------------------------------------------

    def one(self, rotate: bool = True, refine: int | None = None,
            before: tuple = ()) -> Callable[..., tuple[float, ...]]:
        """A plain-Python function ``(u_1, ..., u_M) -> (f_1, ..., f_N)``, no numpy per call.

        The plan's steps as closures over lists; the coupling step is the array path's
        arithmetic in the same order (bit-identical without other steps; a matrix step is
        summed in Python, not by BLAS).  ``refine``: K fixed-point steps, as
        :meth:`decouple`; a vector that does not settle gives NaN forces.
        """
        refine = self.step.refine if refine is None else int(refine)
        plan = self._plan(rotate, refine, before)
        stages = [self._one_step(s, refine) for s in plan.steps]
        if len(stages) == 1:  # eq. (11) alone: no loop over steps
            only = stages[0]
            return lambda *u: tuple(only(u))

        def decouple_one(*u: float) -> tuple[float, ...]:
            x = u
            for stage in stages:
                x = stage(x)
            return tuple(x)

        return decouple_one

    def _one_step(self, step, refine: int) -> Callable:
        if isinstance(step, Couple):
            return self._one_couple(replace(self.step, refine=refine))
        if isinstance(step, TemperatureCorrection):
            c, t0 = step.channel, float(step.t0)
            bg = list(zip(map(float, step.b), map(float, step.g), strict=True))
            z = step.zero_at_t0()
            zs = [0.0] * len(bg) if z is None else z.tolist()

            def temperature(x):
                dt = x[c] - t0
                y = [(v - b * dt) / (1.0 + g * dt) - w for v, (b, g), w in zip(x, bg, zs, strict=True)]
                return y[:c] + y[c + 1:] if step.external else y
            return temperature
        if isinstance(step, InputCorrection):
            pairs = list(zip(map(float, step.offset), map(float, step.gain), strict=True))
            return lambda x: [(v - o) / g for v, (o, g) in zip(x, pairs, strict=True)]
        if isinstance(step, Project | Linear | Rotate):
            rows = [tuple(map(float, r)) for r in np.asarray(step.matrix)]
            return lambda x: [sum(p * v for p, v in zip(r, x, strict=True)) for r in rows]
        raise UnknownStep(step, "the one-vector path")

    def _one_couple(self, step: Couple) -> Callable:
        n, refine, nan = self.n, step.refine, math.nan
        # per input b and interval i: the coefficients (c0, c1, c2, c3) of each fed output
        tables = [[tuple(r[j:j + 4] for j in range(0, len(r), 4)) for r in rows] for rows in self.rows]
        grid = list(zip(self.lo.tolist(), self.inv_step.tolist(), self.intervals.tolist(), tables,
                        strict=True))
        ik, kk, tol = self.inv_k.tolist(), self.k.tolist(), self.step_tol.tolist()
        own = self.own_rows if self.has_own else None
        # per output a, in the array path's order: where its g_ab sit in cells()' list
        order = [[b * (n - 1) + m for b, m in _sum_order(n, a)] for a in range(n)]

        def cells(x, at=None):
            """The g_ab at x of every input b and fed output a (b-major); each input's
            (interval, offset) appended to ``at``, if given.  None outside a table or NaN."""
            g = []
            put = g.append
            for xb, (lo, inv, cnt, table) in zip(x, grid):  # noqa: B905 (len(x) == n)
                t = (xb - lo) * inv
                if not 0.0 <= t < cnt:
                    return None
                i = int(t)
                s = t - i
                for c0, c1, c2, c3 in table[i]:
                    put(horner(c0, c1, c2, c3, s))
                if at is not None:
                    at.append((i, s))
            return g

        def forces(base, g):  # f_a = base_a + g_ab + ..., added left to right
            f = []
            for fa, terms in zip(base, order):  # noqa: B905
                for j in terms:
                    fa += g[j]
                f.append(fa)
            return f

        def exact(u):  # outside a table (at u or at a step), or NaN: the exact path
            f, ok = couple(step, np.array([u], dtype=float))
            return f[0].tolist() if ok[0] else [nan] * n

        def couple_one(u):
            at = None if own is None else []
            g = cells(u, at)
            if g is None:
                return exact(u)
            base = list(map(mul, u, ik))
            if at is not None:
                for a, (i, s) in enumerate(at):
                    base[a] += horner(*own[a][i], s)
            f = forces(base, g)
            if not refine:
                return f
            for _ in range(refine):
                x = list(map(mul, f, kk))
                g = cells(x)
                if g is None:
                    return exact(u)
                f = forces(base, g)
            for a in range(n):
                if not abs(f[a] * kk[a] - x[a]) <= tol[a]:
                    return [nan] * n  # did not settle: no silent forces
            return f

        return couple_one


def _numba_available() -> bool:
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True
