"""Eq. (11) at memory speed: the chi surrogates as look-up tables, for arrays and
for one vector at a time.

Eq. (11) is a sum of one-variable functions: f_a = u_a / k_a + sum over b != a
of g_ab(u_b), with g_ab = -chi_ab / k_a.  Each input voltage u_b feeds two of
them, so one table index per input serves both.  Arrays are cut into blocks
that stay in cache and handed to a small thread pool (numpy releases the GIL in
its loops).  Any block holding an input outside a table's interval, or a NaN,
has those rows recomputed by the exact kernel sum.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .model import CouplingErrorModel

# The fast path promises forces within PROMISE [V] (voltage terms) of the exact
# kernel sum.  An output adds two chi, and a surrogate's recorded max_error is
# the largest error found on its check grid, which at the kernel sum's own
# rounding noise (~1e-11 V) can be exceeded a little between check points.  So
# a surrogate is used only if its recorded error is at most a quarter of the
# promise (fit builds them to a tenth); otherwise that model is evaluated exactly.
PROMISE = 1e-9
MAX_SURROGATE_ERROR = PROMISE / 4
# Up to this many rows, a call goes row by row through the plain-Python evaluator
# (~1 us a row, bit-identical) rather than the block path (~50 us of numpy calls).
SMALL_ROWS = 32
BLOCK_ROWS = 1 << 15  # 32 K rows: measured fastest here; smaller blocks pay more Python per row
# For input axis b, table "A" feeds output (b + 1) % 3 and table "B" output (b + 2) % 3.
_OUT_A = [(b + 1) % 3 for b in range(3)]
_OUT_B = [(b + 2) % 3 for b in range(3)]
# ... so output a gathers A from input (a + 2) % 3 and B from input (a + 1) % 3.
_FROM_A = [2, 0, 1]
_FROM_B = [1, 2, 0]



def usable(surrogate) -> bool:
    """Whether the fast path may use a chi surrogate: present, and recorded within the gate."""
    return surrogate is not None and surrogate.max_error <= MAX_SURROGATE_ERROR


_pool: ThreadPoolExecutor | None = None
_pool_lock = threading.Lock()


def _executor() -> ThreadPoolExecutor:
    global _pool
    with _pool_lock:
        if _pool is None:
            _pool = ThreadPoolExecutor(os.cpu_count() or 1, thread_name_prefix="fsdecouple")
        return _pool


def default_workers() -> int:
    return os.cpu_count() or 1


class FastDecoupler:
    """Eq. (11) from the chi surrogates of a model; exact outside their intervals.

    Build with :meth:`from_model`, which returns None when the model has no
    usable surrogates (then use the exact kernel sum).
    """

    def __init__(self, model: CouplingErrorModel):
        from .config import AXES

        self._model = model
        self._local = threading.local()
        self._small: Callable | None = None
        self.inv_k = 1.0 / np.asarray(model.k, dtype=float)
        self.rotation = (
            None if model.settings.rotation is None else np.asarray(model.settings.rotation, float)
        )
        lo, inv, n = [], [], []
        tab_a: list[list[np.ndarray]] = [[] for _ in range(4)]
        tab_b: list[list[np.ndarray]] = [[] for _ in range(4)]
        self.rows: list[list[tuple[float, ...]]] = []  # per input axis, for decouple_one
        for b, axis in enumerate(AXES):
            sa = model.chi[AXES[_OUT_A[b]] + axis].surrogate
            sb = model.chi[AXES[_OUT_B[b]] + axis].surrogate
            ca = sa.coefficients() * -self.inv_k[_OUT_A[b]]
            cb = sb.coefficients() * -self.inv_k[_OUT_B[b]]
            for j in range(4):
                tab_a[j].append(ca[j])
                tab_b[j].append(cb[j])
            lo.append(sa.lo)
            inv.append(sa.inv_step)
            n.append(sa.intervals)
            self.rows.append([tuple(r) for r in np.concatenate([ca, cb]).T.tolist()])
        self.lo = np.array(lo)
        self.inv_step = np.array(inv)
        self.intervals = np.array(n, dtype=float)
        self.offsets = np.concatenate([[0], np.cumsum(n)[:-1]]).astype(np.intp)
        self.tab_a = [np.concatenate(t) for t in tab_a]
        self.tab_b = [np.concatenate(t) for t in tab_b]
        self.tab_ab = [a + 1j * b for a, b in zip(self.tab_a, self.tab_b, strict=True)]
        self._lo, self._inv_step, self._intervals, self._inv_k = (
            v.reshape(3, 1) for v in (self.lo, self.inv_step, self.intervals, self.inv_k)
        )
        self._offsets = self.offsets.reshape(3, 1)

    @classmethod
    def from_model(cls, model: CouplingErrorModel) -> FastDecoupler | None:
        from .config import AXES

        for axis in AXES:
            pair = [c.surrogate for c in model.chi.values() if c.name[1] == axis]
            if not all(usable(s) for s in pair):
                return None
            if len({(s.lo, s.hi, s.intervals) for s in pair}) != 1:
                return None  # the evaluator shares one index per input voltage
        return cls(model)

    # --- arrays -------------------------------------------------------------------

    def _scratch(self, n: int) -> dict[str, np.ndarray]:
        # One set of work arrays per thread, reused across blocks: a fresh
        # allocation of this size is mmap'ed and page-faulted on every block,
        # which costs more than the arithmetic.
        ws = getattr(self._local, "ws", None)
        if ws is None or ws["t"].shape[1] < n:
            ws = {k: np.empty((3, n)) for k in ("ut", "t", "s")}
            ws.update({k: np.empty((3, n, 2)) for k in ("g", "c", "s2")})
            ws["i"] = np.empty((3, n), dtype=np.intp)
            self._local.ws = ws
        return {k: v[:, :n] for k, v in ws.items()}

    def _block(self, u: np.ndarray, out: np.ndarray, rotate: bool) -> None:
        n = u.shape[0]
        w = self._scratch(n)
        # Work on (3, n) rows: numpy broadcasts a (3,) vector over (n, 3) with an
        # inner loop of length 3, which is many times slower than one long row.
        ut, t, s, i, c = w["ut"], w["t"], w["s"], w["i"], w["c"]
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
        # one complex look-up fetches coefficient j of both chi fed by this input
        g, c, s2 = w["g"], w["c"], w["s2"]
        s2[..., 0] = s
        s2[..., 1] = s
        tab = self.tab_ab
        np.take(tab[3], i, out=g.view(np.complex128)[..., 0], mode="clip")
        for j in (2, 1, 0):
            g *= s2
            np.take(tab[j], i, out=c.view(np.complex128)[..., 0], mode="clip")
            g += c
        ut *= self._inv_k
        for a in range(3):
            ut[a] += g[_FROM_A[a], :, 0]
            ut[a] += g[_FROM_B[a], :, 1]
        if rotate and self.rotation is not None:
            ut = self.rotation @ ut
        for a in range(3):  # column by column: 3x faster than out[:] = ut.T
            out[:, a] = ut[a]
        if not inside:
            bad = ~ok.all(axis=0)
            out[bad] = self._model.decouple(u[bad], rotate=rotate, exact=True)

    def decouple(self, u: np.ndarray, *, rotate: bool = True, workers: int | None = None,
                 block_rows: int = BLOCK_ROWS) -> np.ndarray:
        """Forces [N] by eq. (11) for voltages ``u`` [V], shape (n, 3)."""
        u = np.ascontiguousarray(u, dtype=float).reshape(-1, 3)
        if u.shape[0] <= SMALL_ROWS and (not rotate or self.rotation is None):
            if self._small is None:
                self._small = self.one(rotate=False)
            one = self._small
            return np.array([one(*v) for v in u.tolist()], dtype=float).reshape(-1, 3)
        out = np.empty_like(u)
        starts = range(0, u.shape[0], block_rows)
        workers = default_workers() if workers is None else workers
        if workers <= 1 or len(starts) <= 1:
            for a in starts:
                self._block(u[a:a + block_rows], out[a:a + block_rows], rotate)
            return out
        # contiguous stripes, one task per stripe of blocks, so a thread keeps its
        # cache and the pool sees few submissions
        n_tasks = min(len(starts), 4 * workers)
        per = -(-len(starts) // n_tasks)

        def run(k: int) -> None:
            for a in starts[k * per:(k + 1) * per]:
                self._block(u[a:a + block_rows], out[a:a + block_rows], rotate)

        pool = _executor() if workers == default_workers() else ThreadPoolExecutor(workers)
        try:
            list(pool.map(run, range(-(-len(starts) // per))))
        finally:
            if pool is not _pool:
                pool.shutdown()
        return out

    # --- one vector -----------------------------------------------------------------

    def one(self, rotate: bool = True) -> Callable[[float, float, float], tuple[float, float, float]]:
        """A plain-Python function ``(ux, uy, uz) -> (fx, fy, fz)``, no numpy per call.

        Same arithmetic, in the same order, as :meth:`decouple` (bit-identical
        without a rotation; the rotation is summed in Python, not by BLAS).
        """
        lx, ly, lz = (float(v) for v in self.lo)
        ix, iy, iz = (float(v) for v in self.inv_step)
        nx, ny, nz = (float(v) for v in self.intervals)
        kx, ky, kz = (float(v) for v in self.inv_k)
        rx, ry, rz = self.rows
        rot = None if self.rotation is None or not rotate else [tuple(map(float, r)) for r in self.rotation]
        exact = self._model.decouple

        def decouple_one(ux: float, uy: float, uz: float) -> tuple[float, float, float]:
            tx = (ux - lx) * ix
            ty = (uy - ly) * iy
            tz = (uz - lz) * iz
            if 0.0 <= tx < nx and 0.0 <= ty < ny and 0.0 <= tz < nz:
                i = int(tx)
                s = tx - i
                a0, a1, a2, a3, b0, b1, b2, b3 = rx[i]
                xa = ((a3 * s + a2) * s + a1) * s + a0
                xb = ((b3 * s + b2) * s + b1) * s + b0
                i = int(ty)
                s = ty - i
                a0, a1, a2, a3, b0, b1, b2, b3 = ry[i]
                ya = ((a3 * s + a2) * s + a1) * s + a0
                yb = ((b3 * s + b2) * s + b1) * s + b0
                i = int(tz)
                s = tz - i
                a0, a1, a2, a3, b0, b1, b2, b3 = rz[i]
                za = ((a3 * s + a2) * s + a1) * s + a0
                zb = ((b3 * s + b2) * s + b1) * s + b0
                fx = ux * kx + za + yb
                fy = uy * ky + xa + zb
                fz = uz * kz + ya + xb
            else:  # outside a table, or NaN: the exact kernel sum
                fx, fy, fz = exact([ux, uy, uz], rotate=False, exact=True).tolist()
            if rot is None:
                return fx, fy, fz
            return (
                rot[0][0] * fx + rot[0][1] * fy + rot[0][2] * fz,
                rot[1][0] * fx + rot[1][1] * fy + rot[1][2] * fz,
                rot[2][0] * fx + rot[2][1] * fy + rot[2][2] * fz,
            )

        return decouple_one
