"""The sensor's components and outputs, named in one place.

Axis counts are data, not code: every other module iterates a :class:`Layout`
(or, for the paper's 3-axis sensor, the default tuples below) instead of
spelling out x, y and z.  A load component ``a`` has the prime output
``layout.outputs[a]``; the corrected coupling function chi_ab (eq. 4) is the
coupling error element on output a caused by a load on component b, evaluated
at the prime output u_b.

Chi names: ``"xy"`` for one-letter labels (the 3-axis default, as the paper
writes chi_xy); for longer component names the two labels joined by ``:``,
output first (``"fx:my"`` is the error on the prime output of fx caused by a
load on my).  A label may not contain ``:``, so a name always splits once.
"""

from __future__ import annotations

from dataclasses import dataclass

AXES = ("x", "y", "z")
FORCE_COLUMNS = tuple(f"f{a}" for a in AXES)
VOLTAGE_COLUMNS = tuple(f"u{a}" for a in AXES)
CANONICAL_COLUMNS = ("repetition", "axis", *FORCE_COLUMNS, *VOLTAGE_COLUMNS)
CHI_SEPARATOR = ":"


def chi_pairs(n: int) -> tuple[tuple[int, int], ...]:
    """(output a, input b) of every chi_ab of an n-component sensor, in eq. (11) order.

    Output-major, inputs ascending: for three axes xy, xz, yx, yz, zx, zy.
    """
    return tuple((a, b) for a in range(n) for b in range(n) if a != b)


def chi_name(a: int, b: int, axes=AXES) -> str:
    sep = "" if all(len(x) == 1 for x in axes) else CHI_SEPARATOR
    return f"{axes[a]}{sep}{axes[b]}"


def chi_labels(name: str) -> tuple[str, str]:
    """(output label, input label) of a chi name, ``"xy"`` or ``"fx:my"``."""
    if CHI_SEPARATOR in name:
        out, _, inp = name.partition(CHI_SEPARATOR)
        return out, inp
    return name[0], name[1:]


CHI_NAMES = tuple(chi_name(a, b) for a, b in chi_pairs(len(AXES)))


@dataclass(frozen=True)
class Layout:
    """A sensor's components: axis labels, load columns and prime-output columns.

    ``labels[a]`` names component a in sweeps (the ``axis`` column), per-axis
    figures and chi names; ``loads[a]`` is its load column (and ``apply``'s
    output column); ``outputs[a]`` its prime output.  The paper's sensor is
    :data:`DEFAULT`: x, y, z; fx, fy, fz; ux, uy, uz.  A sensor named in the
    config (``components:``, ``outputs:``) is labelled by its component names.
    """

    labels: tuple[str, ...] = AXES
    loads: tuple[str, ...] = FORCE_COLUMNS
    outputs: tuple[str, ...] = VOLTAGE_COLUMNS

    @classmethod
    def named(cls, components, outputs) -> Layout:
        components, outputs = tuple(components), tuple(outputs)
        if components == FORCE_COLUMNS and outputs == VOLTAGE_COLUMNS:
            return DEFAULT  # today's files: x/y/z labels, chi xy ... zy
        return cls(components, components, outputs)

    @property
    def n(self) -> int:
        return len(self.labels)

    @property
    def m(self) -> int:
        """Output channels: n, or more (M > N: gauges that no component owns, fitting/gauges.py)."""
        return len(self.outputs)

    @property
    def overdetermined(self) -> bool:
        """More outputs than components (M > N): decoupled in the least-squares sense."""
        return len(self.outputs) > len(self.labels)

    def one_output_each(self, what: str) -> None:
        """Refuse, in one line, M > N outputs where ``what`` reads one output per component."""
        if self.overdetermined:
            from .errors import InputError

            raise InputError(f"{what}: {self.m} outputs for {self.n} components (M > N): fit, "
                             f"apply, validate and export handle them, {what} not yet (docs/rigs.md)")

    @property
    def is_default(self) -> bool:
        return self == DEFAULT

    @property
    def canonical(self) -> tuple[str, ...]:
        return ("repetition", "axis", *self.loads, *self.outputs)

    @property
    def pairs(self) -> tuple[tuple[int, int], ...]:
        return chi_pairs(self.n)

    def chi_name(self, a: int, b: int) -> str:
        return chi_name(a, b, self.labels)

    @property
    def chi_names(self) -> tuple[str, ...]:
        return tuple(self.chi_name(a, b) for a, b in self.pairs)

    def pair(self, name: str) -> tuple[int, int]:
        """(output a, input b) of the chi named ``name``."""
        out, inp = chi_labels(name)
        return self.labels.index(out), self.labels.index(inp)

    def index(self, label: str) -> int:
        return self.labels.index(label)

    def label_map(self) -> dict[str, str]:
        """Every accepted ``axis`` cell (lower case) to its label: the label, or the load name."""
        out = {lab.lower(): lab for lab in self.labels}
        out.update({load.lower(): lab for load, lab in zip(self.loads, self.labels, strict=True)})
        return out


DEFAULT = Layout()


def labels_in(records) -> list[str]:
    """The component labels of result records (``axis`` keys), in the order given; x, y, z if none."""
    return list(dict.fromkeys(r["axis"] for r in records or ())) or list(AXES)


def load_name(label: str) -> str:
    """A label's load column: ``fx`` for the x axis, a named component as it is."""
    return f"f{label}" if label in AXES else label


class NamedChi:
    """Mixin for a chi_ab named ``"ab"`` or ``"a:b"``: its output and input index.

    ``pair`` (output, input), when the chi carries one, wins; otherwise the name
    is read with the default x, y, z labels.
    """

    name: str

    def _pair(self) -> tuple[int, int]:
        pair = getattr(self, "pair", None)
        if pair is not None:
            return pair
        return DEFAULT.pair(self.name)

    @property
    def output_axis(self) -> int:
        return self._pair()[0]

    @property
    def input_axis(self) -> int:
        return self._pair()[1]


def component_key(label: str) -> str:
    """A component's name as compared across models: case aside, and ATI's torques
    (``tx``, data/ati_model.py) as fsdecouple's moments (``mx``)."""
    label = label.lower()
    return "m" + label[1:] if len(label) == 2 and label[0] == "t" else label
