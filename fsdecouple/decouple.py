"""Eq. (11), once, over (n, N) arrays: the exact path and the table path.

    f_a = omega_a^-1 [u_a - sum_{b != a} chi_ab(u_b)]                    eq. (11)

with omega_a^-1(v) = v / k_aa (eq. 13 form).  N is the number of components
(len(k)); nothing here knows their names.

* :func:`decouple_exact` evaluates every chi as given (the SVR's kernel sum, or
  any other callable such as the RBF baseline's networks);
* :class:`TableDecoupler` evaluates the same sum from the chi surrogates
  (:mod:`fsdecouple.surrogate`) at memory speed, and hands rows outside the
  tables (or with a NaN) to the exact path.  Eq. (11) is a sum of one-variable
  functions, ``f_a = u_a / k_a + sum_{b != a} g_ab(u_b)`` with g_ab = -chi_ab / k_a,
  and the N - 1 chi fed by input b share one grid, so one table index per input
  serves them all.
* :meth:`TableDecoupler.one` is the same table arithmetic for one vector in plain
  Python, generated for N from the template below and tested bit for bit
  against the array path.
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
# (~1 us a row, bit-identical) rather than the block path (~50 us of numpy calls).
SMALL_ROWS = 32
BLOCK_ROWS = 1 << 15  # 32 K rows: measured fastest here; smaller blocks pay more Python per row


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
                   rotation: np.ndarray | None = None) -> np.ndarray:
    """Eq. (11) with every chi evaluated as given; ``u`` (n, N) zero-corrected outputs.

    ``rotation`` (N, N), if given, takes the forces from the sensor frame to the
    reference frame (end of Section 2.3).
    """
    f = (u - coupling_errors(u, chis)) / k
    if rotation is not None:
        f = f @ np.asarray(rotation).T
    return f


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
        The table of every chi_ab; the N - 1 tables of one input b share a grid.
    exact : callable
        ``exact(u, rotate) -> f`` for rows the tables do not cover.
    rotation : ndarray, shape (N, N), optional
        Sensor frame to reference frame.

    Build with :meth:`from_chis`, which returns None when a table is missing or
    unusable (then every row takes the exact path).
    """

    def __init__(self, k: np.ndarray, surrogates: dict[tuple[int, int], object],
                 exact: Callable[[np.ndarray, bool], np.ndarray], rotation=None):
        n = len(k)
        self.n = n
        self._exact = exact
        self._local = threading.local()
        self._small: Callable | None = None
        self.inv_k = 1.0 / np.asarray(k, dtype=float)
        self.rotation = None if rotation is None else np.asarray(rotation, dtype=float)
        lo, inv, count = [], [], []
        tabs: list[list[np.ndarray]] = [[] for _ in range(4)]
        self.rows: list[list[tuple[float, ...]]] = []  # per input, for the one-vector path
        for b in range(n):
            fed = [surrogates[(a, b)] for a in _fed_order(n, b)]
            coef = [s.coefficients() * -self.inv_k[a] for a, s in zip(_fed_order(n, b), fed,
                                                                        strict=True)]
            for j in range(4):  # (intervals, N - 1): one row fetches coefficient j of every chi
                tabs[j].append(np.stack([c[j] for c in coef], axis=1))
            lo.append(fed[0].lo)
            inv.append(fed[0].inv_step)
            count.append(fed[0].intervals)
            self.rows.append([tuple(r) for r in np.concatenate(coef).T.tolist()])
        self.lo = np.array(lo)
        self.inv_step = np.array(inv)
        self.intervals = np.array(count, dtype=float)
        self.offsets = np.concatenate([[0], np.cumsum(count)[:-1]]).astype(np.intp)
        self.tab = [np.ascontiguousarray(np.concatenate(t)) for t in tabs]
        self._lo, self._inv_step, self._intervals, self._inv_k = (
            v.reshape(n, 1) for v in (self.lo, self.inv_step, self.intervals, self.inv_k)
        )
        self._offsets = self.offsets.reshape(n, 1)
        self._sum = [_sum_order(n, a) for a in range(n)]

    @classmethod
    def from_chis(cls, k, chis: Iterable, exact, rotation=None, full_scale_output=None
                  ) -> TableDecoupler | None:
        """From chi objects with ``output_axis``, ``input_axis`` and ``surrogate``.

        ``full_scale_output`` (N,): |k_a| F_FS,a, to which the gate is relative.
        """
        tables = {(c.output_axis, c.input_axis): c.surrogate for c in chis}
        n = len(k)
        u_fs = np.ones(n) if full_scale_output is None else np.asarray(full_scale_output, float)
        for b in range(n):
            fed = [tables.get((a, b)) for a in range(n) if a != b]
            if not all(usable(tables.get((a, b)), u_fs[a]) for a in range(n) if a != b):
                return None
            if len({(s.lo, s.hi, s.intervals) for s in fed}) != 1:
                return None  # the evaluator shares one index per input
        return cls(k, tables, exact, rotation)

    # --- arrays -------------------------------------------------------------------

    def _scratch(self, rows: int) -> dict[str, np.ndarray]:
        # One set of work arrays per thread, reused across blocks: a fresh
        # allocation of this size is mmap'ed and page-faulted on every block,
        # which costs more than the arithmetic.
        ws = getattr(self._local, "ws", None)
        n, m = self.n, self.n - 1
        if ws is None or ws["t"].shape[1] < rows:
            ws = {k: np.empty((n, rows)) for k in ("ut", "t", "s")}
            ws.update({k: np.empty((n, rows, m)) for k in ("g", "c", "s2")})
            ws["i"] = np.empty((n, rows), dtype=np.intp)
            self._local.ws = ws
        return {k: v[:, :rows] for k, v in ws.items()}

    def _block(self, u: np.ndarray, out: np.ndarray, rotate: bool, covered) -> None:
        w = self._scratch(u.shape[0])
        # Work on (N, n) rows: numpy broadcasts an (N,) vector over (n, N) with an
        # inner loop of length N, which is many times slower than one long row.
        ut, t, s, i = w["ut"], w["t"], w["s"], w["i"]
        np.copyto(ut, u.T)
        np.subtract(ut, self._lo, out=t)
        t *= self._inv_step
        inside = bool(t.min() >= 0.0 and np.all(t.max(axis=1) < self.intervals))
        if not inside:  # also a NaN: min/max propagate it and the test fails
            ok = (t >= 0) & (t < self._intervals)
            np.copyto(t, 0.0, where=~ok)
        np.copyto(i, t, casting="unsafe")  # truncation = floor, as t >= 0
        np.subtract(t, i, out=s)
        i += self._offsets
        # one row of a table holds coefficient j of all N - 1 chi fed by an input
        g, c, s2 = w["g"], w["c"], w["s2"]
        for m in range(self.n - 1):
            s2[..., m] = s
        np.take(self.tab[3], i, axis=0, out=g, mode="clip")
        for j in (2, 1, 0):  # Horner
            g *= s2
            np.take(self.tab[j], i, axis=0, out=c, mode="clip")
            g += c
        ut *= self._inv_k
        for a, terms in enumerate(self._sum):
            for b, m in terms:
                ut[a] += g[b, :, m]
        if rotate and self.rotation is not None:
            ut = self.rotation @ ut
        for a in range(self.n):  # column by column: 3x faster than out[:] = ut.T
            out[:, a] = ut[a]
        if not inside:
            bad = ~ok.all(axis=0)
            out[bad] = self._exact(u[bad], rotate)
            if covered is not None:
                covered[bad] = False

    def decouple(self, u: np.ndarray, *, rotate: bool = True, workers: int | None = None,
                 block_rows: int = BLOCK_ROWS, covered: np.ndarray | None = None) -> np.ndarray:
        """Forces by eq. (11) for zero-corrected outputs ``u``, shape (n, N).

        ``covered``, a boolean array of n rows, is set False where a row left the
        tables (outside their intervals, or NaN) and took the exact path.
        """
        u = np.ascontiguousarray(u, dtype=float).reshape(-1, self.n)
        if covered is not None:
            covered[:] = True
        if u.shape[0] <= SMALL_ROWS and covered is None and (not rotate or self.rotation is None):
            if self._small is None:
                self._small = self.one(rotate=False)
            one = self._small
            return np.array([one(*v) for v in u.tolist()], dtype=float).reshape(-1, self.n)
        out = np.empty_like(u)
        starts = range(0, u.shape[0], block_rows)
        workers = default_workers() if workers is None else workers

        def run_blocks(chunk) -> None:
            for a in chunk:
                self._block(u[a:a + block_rows], out[a:a + block_rows], rotate,
                            None if covered is None else covered[a:a + block_rows])

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

    def one(self, rotate: bool = True) -> Callable[..., tuple[float, ...]]:
        """A plain-Python function ``(u_1, ..., u_N) -> (f_1, ..., f_N)``, no numpy per call.

        Generated for N from :func:`one_vector_source`: the array path's
        arithmetic in the same order (bit-identical without a rotation; the
        rotation is summed in Python, not by BLAS).
        """
        rot = None if self.rotation is None or not rotate else \
            [tuple(map(float, r)) for r in self.rotation]
        exact = self._exact
        env = {
            "rows": self.rows, "lo": [float(v) for v in self.lo],
            "inv": [float(v) for v in self.inv_step], "cnt": [float(v) for v in self.intervals],
            "ik": [float(v) for v in self.inv_k], "rot": rot,
            "exact": lambda *u: exact(np.array([u], dtype=float), False)[0].tolist(),
        }
        namespace: dict = {}
        exec(compile(one_vector_source(self.n, rot is not None), "<fsdecouple.decouple.one>",
                     "exec"), namespace)
        return namespace["make"](**env)


def one_vector_source(n: int, rotate: bool) -> str:
    """Python source of the one-vector evaluator of :meth:`TableDecoupler.one` for N = n.

    The statements follow :meth:`TableDecoupler._block` step by step: the table
    index ``t = (u_b - lo_b) * inv_step_b``, a Horner step per chi, then
    ``f_a = u_a / k_a + sum g_ab`` in :func:`_sum_order`.
    """
    u = [f"u{b}" for b in range(n)]
    lines = ["def make(rows, lo, inv, cnt, ik, rot, exact):"]
    for b in range(n):
        lines.append(f"    r{b}, l{b}, i{b}, n{b}, k{b} = rows[{b}], lo[{b}], inv[{b}], cnt[{b}], ik[{b}]")
    if rotate:
        lines.append(f"    ({', '.join(f'R{a}' for a in range(n))},) = rot")
    lines.append(f"    def decouple_one({', '.join(u)}):")
    for b in range(n):
        lines.append(f"        t{b} = ({u[b]} - l{b}) * i{b}")
    lines.append("        if " + " and ".join(f"0.0 <= t{b} < n{b}" for b in range(n)) + ":")
    for b in range(n):
        coef = [f"c{m}_{j}" for m in range(n - 1) for j in range(4)]
        lines += [f"            i = int(t{b})", f"            s = t{b} - i",
                  f"            {', '.join(coef)} = r{b}[i]"]
        for m in range(n - 1):
            lines.append(f"            g{b}_{m} = ((c{m}_3 * s + c{m}_2) * s + c{m}_1) * s + c{m}_0")
    for a in range(n):
        terms = "".join(f" + g{b}_{m}" for b, m in _sum_order(n, a))
        lines.append(f"            f{a} = {u[a]} * k{a}{terms}")
    lines += ["        else:  # outside a table, or NaN: the exact kernel sum",
              f"            {', '.join(f'f{a}' for a in range(n))}, = exact({', '.join(u)})"]
    f = [f"f{a}" for a in range(n)]
    if rotate:
        rows = [" + ".join(f"R{a}[{b}] * {f[b]}" for b in range(n)) for a in range(n)]
        lines.append(f"        return ({', '.join(rows)},)")
    else:
        lines.append(f"        return ({', '.join(f)},)")
    lines.append("    return decouple_one")
    return "\n".join(lines) + "\n"
