"""What the C header holds: the plan that ``export/header.py`` decides and checks and
``export/c_source.py`` writes out, and what an export returns."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..core.model import RANGE_MARGIN
from ..errors import printable


@dataclass
class ChiPlan:
    """One chi_ab as the header holds it: kernel sum, and table (4, n) or None."""

    out: int
    inp: int
    gamma: float
    sv: np.ndarray
    coef: np.ndarray
    rho: float
    in_scale: float
    out_scale: float
    exact: Any  # the model's Chi: exact kernel sum [V] of prime voltages [V]
    lo: float = 0.0
    hi: float = 0.0
    table: np.ndarray | None = None  # power-basis coefficients c0..c3 per interval
    table_error: float = 0.0  # measured max |table - kernel sum| [V]

    @property
    def inv_step(self) -> float:
        return self.table.shape[1] / (self.hi - self.lo)  # as ChiSurrogate.inv_step


@dataclass
class ExportPlan:
    """Everything the header holds; see :func:`export_header`."""

    prefix: str
    precision: str
    n: int
    k: np.ndarray
    chis: list[ChiPlan]
    rotation: np.ndarray | None
    full_scale: np.ndarray
    calibrated_range: np.ndarray
    range_limits: np.ndarray  # apply's extrapolation thresholds, (n, 2)
    limits: list  # (lo, hi) or (None, None) per channel: saturation
    refine: int
    digest: str
    format_version: int
    sensor: str
    load_unit: str = "N"
    output_unit: str = "V"
    version: str = ""
    range_margin: float = RANGE_MARGIN
    table_max_error: float = 0.0  # max |df| / full scale from the tables
    float_max_error: float = 0.0
    range_limits_f: np.ndarray | None = None
    limits_f: list = field(default_factory=list)
    selftest_u: np.ndarray | None = None
    selftest_f: np.ndarray | None = None
    selftest_tol: np.ndarray | None = None
    selftest_status: list = field(default_factory=list)
    selftest_note: str = ""
    model: Any = None  # the model exported: the reference of every check
    projection: np.ndarray | None = None  # M > N outputs: v = P u first (fitting/gauges.py)
    matrix: np.ndarray | None = None  # a linear model's f = C u: no chi, no tables

    @property
    def method(self) -> str:
        return "svr" if self.matrix is None else "linear"

    @property
    def m(self) -> int:
        """Outputs the function takes: N, or M > N with a projection."""
        return self.n if self.projection is None else self.projection.shape[1]

    def lift(self, v: np.ndarray) -> np.ndarray:
        """Outputs u (rows, M) whose v = P u is ``v`` (rows, N): u = P^+ v; v itself for M = N."""
        v = np.asarray(v, dtype=float)
        return v if self.projection is None else v @ np.linalg.pinv(self.projection).T

    def project(self, u: np.ndarray, dtype=float) -> np.ndarray:
        """v = P u as the C computes it: left to right, in ``dtype``; u itself for M = N."""
        u = np.asarray(u, dtype=dtype)
        if self.projection is None:
            return u
        p = self.projection.astype(dtype)
        v = np.empty((len(u), self.n), dtype=dtype)
        for a in range(self.n):
            acc = p[a, 0] * u[:, 0]
            for j in range(1, self.m):
                acc = acc + p[a, j] * u[:, j]
            v[:, a] = acc
        return v

    @property
    def terms_per_output(self) -> int:
        """Chi summed into one output: N - 1 cross chi, and an own-load chi_aa if any."""
        return max([sum(c.out == a for c in self.chis) for a in range(self.n)] + [1])

    @property
    def table_bytes(self) -> int:
        size = 4 if self.precision == "float" else 8
        return sum(c.table.size * size for c in self.chis if c.table is not None)

    @property
    def kernel_bytes(self) -> int:
        return sum(16 * c.sv.size for c in self.chis)


@dataclass
class ExportResult:
    """What ``export_header`` wrote and what it promises."""

    path: Path
    precision: str
    prefix: str
    n_components: int
    intervals: dict[str, int | None]
    table_bytes: int
    kernel_bytes: int
    table_max_error: float  # fraction of full-scale load
    float_max_error: float | None
    method: str = "svr"

    def to_dict(self) -> dict[str, Any]:
        return {"path": str(self.path), "precision": self.precision, "prefix": self.prefix,
                "n_components": self.n_components, "intervals": self.intervals,
                "table_bytes": self.table_bytes, "kernel_bytes": self.kernel_bytes,
                "table_max_error": self.table_max_error, "float_max_error": self.float_max_error,
                "method": self.method}

    def summary_lines(self) -> list[str]:
        counts = [v for v in self.intervals.values() if v is not None]
        tables = (f"{len(counts)} tables of {min(counts)}-{max(counts)} intervals"
                  if counts else "no tables (kernel sums only)")
        if self.method == "linear":
            tables = "the least-squares calibration matrix f = C u (no chi, no tables)"
        lines = [f"wrote {printable(self.path)}: {self.n_components} components, {self.precision}, {tables}",
                 f"table bytes {self.table_bytes}, support-vector bytes {self.kernel_bytes}",
                 f"table error <= {self.table_max_error:.3g} of full-scale load"]
        if self.float_max_error is not None:
            lines.append(f"float error <= {self.float_max_error:.3g} of full-scale load "
                         f"({self.prefix.upper()}FLOAT_MAX_ERROR in the header)")
        return lines
