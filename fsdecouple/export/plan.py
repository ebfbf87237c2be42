"""What the C header holds: the model's decoupling plan with the header's tables, which
``export/header.py`` decides and checks and ``export/c_source.py`` writes out, and what an
export returns."""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import takewhile
from pathlib import Path
from typing import Any

import numpy as np

from ..core.model import RANGE_MARGIN
from ..core.plan import (
    Couple,
    InputCorrection,
    Linear,
    Plan,
    Project,
    Rotate,
    TemperatureCorrection,
    Term,
    walk,
)
from ..errors import printable


@dataclass
class ExportPlan:
    """Everything the header holds; see :func:`export_header`.

    ``plan`` is the model's decoupling plan (:mod:`fsdecouple.core.plan`) with the
    header's tables in its terms (each a :class:`~fsdecouple.core.surrogate.ChiSurrogate`,
    or None for a kernel sum only): what the C text, the float emulation and the exact
    reference all evaluate.
    """

    prefix: str
    precision: str
    plan: Plan
    full_scale: np.ndarray
    calibrated_range: np.ndarray
    range_limits: np.ndarray  # apply's extrapolation thresholds, (n, 2)
    limits: list  # (lo, hi) or (None, None) per channel: saturation
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
    temperature_span_f: tuple[float, float] | None = None  # the span's, for a float input
    limits_f: list = field(default_factory=list)
    selftest_u: np.ndarray | None = None
    selftest_f: np.ndarray | None = None
    selftest_tol: np.ndarray | None = None
    selftest_status: list = field(default_factory=list)
    selftest_note: str = ""
    model: Any = None  # the model exported

    @property
    def n(self) -> int:
        return self.plan.n_components

    @property
    def m(self) -> int:
        """Outputs the function takes: N, or M > N with a projection."""
        return self.plan.n_outputs

    @property
    def chis(self) -> list[Term]:
        """The chi of eq. (11), in the plan's order (own-load chi_aa last)."""
        return list(self.plan.terms)

    @property
    def k(self) -> np.ndarray:
        return np.asarray(self.model.k, dtype=float)

    @property
    def refine(self) -> int:
        c = self.plan.couple
        return 0 if c is None else c.refine

    def _matrix(self, kind) -> np.ndarray | None:
        step = self.plan.step(kind)
        return None if step is None else step.matrix

    @property
    def rotation(self) -> np.ndarray | None:
        return self._matrix(Rotate)

    @property
    def projection(self) -> np.ndarray | None:
        return self._matrix(Project)

    @property
    def matrix(self) -> np.ndarray | None:
        """A linear model's f = C u: no chi, no tables."""
        return self._matrix(Linear)

    @property
    def method(self) -> str:
        return "svr" if self.matrix is None else "linear"

    @property
    def temperature(self) -> TemperatureCorrection | None:
        return self.plan.step(TemperatureCorrection)

    @property
    def zero(self) -> InputCorrection | None:
        """The zero step on raw outputs (a ``zero: intercept`` model's fitted offsets), or None."""
        return next((s for s in self.plan.steps if isinstance(s, InputCorrection) and s.zero), None)

    def lift(self, v: np.ndarray, rng=None) -> np.ndarray:
        """Inputs u (rows, m) whose v = P u is ``v`` (rows, N): u = P^+ v; v itself for M = N.

        A ``zero: intercept`` model: raw outputs, its fitted offsets added.
        A temperature model: the temperature set to T0 + dt, dt cycling over the calibrated
        span's half-width each side (random with ``rng``; 0.05 |T0| or 1 without a span),
        and the outputs made raw at that temperature, so the corrected ones are ``v``'s.
        """
        v = np.asarray(v, dtype=float)
        u = v if self.projection is None else v @ np.linalg.pinv(self.projection).T
        step = self.temperature
        if step is None:  # raw outputs: the default zero (fitted offsets) added back
            return u if self.zero is None else u + self.zero.offset
        terms = self.model.temperature
        half = (terms.span[1] - terms.span[0]) / 2 if terms.span is not None else \
            0.05 * abs(step.t0) or 1.0
        half = half or 1.0
        dt = (rng.uniform(-1.5, 1.5, len(u)) if rng is not None
              else np.resize([0.0, 1.0, -1.0, 1.5, -0.5], len(u))) * half
        x = np.insert(u, step.channel, 0.0, axis=1) if step.external else u.copy()
        x = x * (1.0 + step.g * dt[:, None]) + step.b * dt[:, None]  # u_i(T) of u_i(T0)
        x[:, step.channel] = step.t0 + dt
        return x

    def prime(self, u: np.ndarray) -> np.ndarray:
        """The outputs eq. (11) (or f = C u) acts on: the plan's steps before it, in double."""
        head = Plan(tuple(takewhile(lambda s: not isinstance(s, Couple | Linear), self.plan.steps)),
                    self.m, self.m)
        x = walk(head, u, None)
        return x

    @property
    def terms_per_output(self) -> int:
        """Chi summed into one output: N - 1 cross chi, and an own-load chi_aa if any."""
        return max([sum(c.out == a for c in self.chis) for a in range(self.n)] + [1])

    @property
    def table_bytes(self) -> int:
        size = 4 if self.precision == "float" else 8
        return sum(4 * c.table.intervals * size for c in self.chis if c.table is not None)

    @property
    def kernel_bytes(self) -> int:
        return sum(16 * c.chi.support_vectors.size for c in self.chis)


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
    imported: bool = False  # a factory matrix read from an ATI file (data/ati_model.py)

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
            tables = ("the factory calibration matrix f = W u (no chi, no tables)" if self.imported
                      else "the least-squares calibration matrix f = C u (no chi, no tables)")
        lines = [f"wrote {printable(self.path)}: {self.n_components} components, {self.precision}, {tables}",
                 f"table bytes {self.table_bytes}, support-vector bytes {self.kernel_bytes}",
                 f"table error <= {self.table_max_error:.3g} of full-scale load"]
        if self.float_max_error is not None:
            lines.append(f"float error <= {self.float_max_error:.3g} of full-scale load "
                         f"({self.prefix.upper()}FLOAT_MAX_ERROR in the header)")
        return lines
