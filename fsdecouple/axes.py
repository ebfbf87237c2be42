"""The sensor's components and outputs, named in one place.

Axis counts are data, not code: every other module iterates these tuples (or the
chi names derived from them) instead of spelling out x, y and z.  A load
component ``a`` has the prime output ``OUTPUT_COLUMNS[a]``; the corrected
coupling function chi_ab (eq. 4) is the coupling error element on output a
caused by a load on component b, evaluated at the prime output u_b.
"""

from __future__ import annotations

AXES = ("x", "y", "z")
FORCE_COLUMNS = tuple(f"f{a}" for a in AXES)
VOLTAGE_COLUMNS = tuple(f"u{a}" for a in AXES)
CANONICAL_COLUMNS = ("repetition", "axis", *FORCE_COLUMNS, *VOLTAGE_COLUMNS)


def chi_pairs(n: int) -> tuple[tuple[int, int], ...]:
    """(output a, input b) of every chi_ab of an n-component sensor, in eq. (11) order.

    Output-major, inputs ascending: for three axes xy, xz, yx, yz, zx, zy.
    """
    return tuple((a, b) for a in range(n) for b in range(n) if a != b)


def chi_name(a: int, b: int, axes=AXES) -> str:
    return f"{axes[a]}{axes[b]}"


CHI_NAMES = tuple(chi_name(a, b) for a, b in chi_pairs(len(AXES)))


class NamedChi:
    """Mixin for a chi_ab named ``"ab"`` (``name`` attribute): its output and input index."""

    name: str

    @property
    def output_axis(self) -> int:
        return AXES.index(self.name[0])

    @property
    def input_axis(self) -> int:
        return AXES.index(self.name[1])
