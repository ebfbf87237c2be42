"""Frames: the rotation of a 3-axis sensor's forces and a 6-axis sensor's wrench transform.

The paper rotates the decoupled forces from the sensor frame into the reference
frame (end of Section 2.3): ``F' = R F`` (config ``rotation:``, 3 x 3).  A six-axis
sensor also measures moments, about its own measuring point; in the reference
frame they are wanted about the reference frame's origin.  Config
``frame: {rotation: R, origin: r}`` applies, after eq. (11),

    F' = R F,    M' = R M + r x (R F),

with ``r`` the sensor's measuring point in the reference frame (the vector from
the reference origin to it), in the length unit of the moments (m for N·m, mm
for N·mm).  The sign follows from M_O = M_P + (P - O) x F for a force acting
through P.  Both are linear, so the transform is the 6 x 6 matrix

    T = [[R, 0], [[r]_x R, R]]

applied to ``(fx, fy, fz, mx, my, mz)`` by the same code path as the 3 x 3 rotation
(:mod:`fsdecouple.core.decouple`).  The components must be forces then moments, x, y, z.

ATI's convention (ATIDAQ's tool transform, ftconfig.c) is the same transform written
with the displacement d of the tool point from the sensor origin, in the sensor
frame: ``frame: {rotation: R, displacement: d}`` applies

    F' = R F,    T' = R (T - d x F),

which is the form above with r = -R d (``T = [[R, 0], [-R [d]x, R]]``).  ATI's angles
(Rx, Ry, Rz in degrees) give R by :func:`ati_rotation`, and ``frame: {angles: [Rx, Ry,
Rz]}`` takes them as ATIDAQ does.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .errors import ConfigError


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(f"{where}: expected a number, found {value!r}")
    if not np.isfinite(value):
        raise ConfigError(f"{where}: expected a finite number, found {value!r}")
    return float(value)


def parse_rotation(raw: Any, where: str) -> tuple[tuple[float, float, float], ...] | None:
    """A 3 x 3 rotation (orthonormal rows, det +1) from the config, or None."""
    if raw is None:
        return None
    if not (isinstance(raw, list) and len(raw) == 3 and all(
        isinstance(r, list) and len(r) == 3 for r in raw
    )):
        raise ConfigError(f"{where}: expected a 3x3 list of lists, found {raw!r}")
    rows = tuple(
        tuple(_number(v, f"{where}[{i}][{j}]") for j, v in enumerate(r)) for i, r in enumerate(raw)
    )
    # A rotation from the sensor frame to the reference frame (end of Section 2.3)
    # must be orthonormal with det +1, or forces would be scaled or mirrored.
    m = [[rows[i][j] for j in range(3)] for i in range(3)]
    for i in range(3):
        for j in range(3):
            dot = sum(m[i][k] * m[j][k] for k in range(3))
            if abs(dot - (1.0 if i == j else 0.0)) > 1e-6:
                raise ConfigError(f"{where}: not a rotation matrix (rows are not orthonormal)")
    det = (
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    )
    if det < 0:
        raise ConfigError(f"{where}: determinant is -1, a reflection, not a rotation")
    return rows


def ati_rotation(angles) -> np.ndarray:
    """R of ATI's tool transform from (Rx, Ry, Rz) [degrees], as ATIDAQ's TTM builds it.

    Rows (cy cz, sx sy cz + cx sz, sx sz - cx sy cz), (-cy sz, cx cz - sx sy sz,
    sx cz + cx sy sz), (sy, -sx cy, cx cy), with s., c. the sines and cosines.
    """
    (sx, sy, sz), (cx, cy, cz) = (np.sin(np.radians(np.asarray(angles, dtype=float))),
                                  np.cos(np.radians(np.asarray(angles, dtype=float))))
    return np.array([[cy * cz, sx * sy * cz + cx * sz, sx * sz - cx * sy * cz],
                     [-cy * sz, cx * cz - sx * sy * sz, sx * cz + cx * sy * sz],
                     [sy, -sx * cy, cx * cy]])


def wrench_transform(r, d) -> np.ndarray:
    """ATI's 6 x 6 ``[[R, 0], [-R [d]x, R]]``: F' = R F, T' = R (T - d x F) on (F, T)."""
    r = np.asarray(r, dtype=float)
    dx, dy, dz = (float(v) for v in d)
    cross = np.array([[0.0, -dz, dy], [dz, 0.0, -dx], [-dy, dx, 0.0]])  # [d]x F = d x F
    t = np.zeros((6, 6))
    t[:3, :3] = r
    t[3:, 3:] = r
    t[3:, :3] = -r @ cross
    return t


@dataclass(frozen=True)
class Frame:
    """The reference frame of a six-axis sensor: ``rotation`` R (sensor to reference)
    and ``origin`` r, the sensor's measuring point in the reference frame; or, ATI's way,
    ``displacement`` d, the tool point from the sensor origin in the sensor frame."""

    rotation: tuple[tuple[float, float, float], ...] = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0),
                                                        (0.0, 0.0, 1.0))
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    displacement: tuple[float, float, float] | None = None  # ATI's d: T' = R (T - d x F)

    def to_dict(self) -> dict[str, Any]:
        d = {"rotation": [list(r) for r in self.rotation], "origin": list(self.origin)}
        if self.displacement is not None:  # files from before it keep their bytes
            del d["origin"]
            d["displacement"] = list(self.displacement)
        return d

    def matrix(self) -> np.ndarray:
        """T, 6 x 6: ``(F', M') = T (F, M)``."""
        r = np.asarray(self.rotation, dtype=float)
        if self.displacement is not None:
            return wrench_transform(r, self.displacement)
        x, y, z = self.origin
        cross = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])  # [r]_x v = r x v
        t = np.zeros((6, 6))
        t[:3, :3] = r
        t[3:, 3:] = r
        t[3:, :3] = cross @ r
        return t


def parse_frame(raw: Any, where: str, n_components: int) -> Frame:
    """``frame: {rotation: 3x3, origin: [x, y, z]}`` for a six-axis sensor."""
    if n_components != 6:
        raise ConfigError(f"{where}: a frame moves moments, for a sensor of 6 components "
                          f"(forces then moments); this one has {n_components}: use rotation:")
    if not isinstance(raw, dict):
        raise ConfigError(f"{where}: expected a mapping with rotation and origin, found {raw!r}")
    keys = ("angles", "displacement", "origin", "rotation")
    unknown = [k for k in raw if k not in keys]
    if unknown:
        raise ConfigError(f"{where}: unknown key {unknown[0]!r}; allowed: {', '.join(keys)}")
    for a, b in (("origin", "displacement"), ("rotation", "angles")):
        if a in raw and b in raw:
            raise ConfigError(f"{where}: give {a} or {b}, not both ({b} is ATI's form of the same "
                              "transform, docs/six-axis.md)")
    kw: dict[str, Any] = {}
    if raw.get("rotation") is not None:
        kw["rotation"] = parse_rotation(raw["rotation"], f"{where}: rotation")
    if "angles" in raw:
        angles = _triple(raw["angles"], f"{where}: angles", "[Rx, Ry, Rz] in degrees")
        kw["rotation"] = tuple(tuple(float(v) for v in row) for row in ati_rotation(angles))
    for key in ("origin", "displacement"):
        if key in raw:
            kw[key] = _triple(raw[key], f"{where}: {key}", "[x, y, z]")
    return Frame(**kw)


def _triple(value: Any, where: str, what: str) -> tuple[float, float, float]:
    if not (isinstance(value, list) and len(value) == 3):
        n = len(value) if isinstance(value, list) else None
        raise ConfigError(f"{where}: expected {what}, three numbers, found "
                          + (f"{n} values" if n is not None else repr(value)))
    return tuple(_number(v, f"{where}[{i}]") for i, v in enumerate(value))
