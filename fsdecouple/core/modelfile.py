"""The model file: one JSON document, versioned apart from the package, with a digest.

Like skops, the file carries ``format`` and a ``format_version`` of its own and
refuses files from a newer format; a SHA-256 over its canonical content catches
hand edits and corrupted transfers.  Written sorted, without NaN, atomically.
"""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from .. import __version__
from ..config import settings_from_dict
from ..errors import InputError, ModelFileError, excerpt
from ..files.inputs import MODEL_LIMIT, read_bounded
from ..files.outputs import atomic_write
from ..schema import LEGACY_EXTRAPOLATION
from .decouple import MAX_SURROGATE_ERROR, usable
from .interval_data import MAX_FULL_SCALES, MIN_MEAN_SQUARE, check_interval_data, numbers
from .model import Chi, CouplingErrorModel, FitReport
from .modeljson import dump_forms, join_indented
from .surrogate import spot_check
from .temperature import TemperatureTerms

FORMAT = "fsdecouple.model"
FORMAT_VERSION = 3
# Version 2 adds: ``method`` (svr | linear) and ``matrix`` for linear models,
# ``settings.units``, and ``report.verdict``.  Version 1 files read as svr models
# in newtons and volts.  Version 3 adds ``settings.components`` and ``outputs``
# (an N-component sensor, axes.Layout; chi keyed "fx:fy"), per-column units and
# ``settings.frame``; a 3-axis model reads and writes as before otherwise.  An svr
# model may carry ``matrix`` too (the least-squares matrix of its calibration, which
# ``validate`` sets beside it); readers that do not know it ignore it, and it is
# covered by the digest as every key is, so the version stays 3.
# Version 4 adds ``chi_own``: the own-load chi_aa of a joint fit of rig rows
# (fitting/joint.py).  Only a model that has them is written as version 4, so that an
# older fsdecouple refuses it instead of decoupling without them; others stay version 3.
OWN_FORMAT_VERSION = 4
# Version 5 adds ``projection``: P = K^+ (N x M) of a sensor with M > N outputs
# (fitting/gauges.py), whose settings name M outputs; only such models are version 5.
GAUGES_FORMAT_VERSION = 5
# Version 6 adds imported linear models (a factory matrix, data/ati_cal.py): ``method``
# linear with no chi, k = 1 and ``projection`` = ``matrix`` (N x M, its forces bound the
# range), and ``temperature`` (core/temperature.py: the temperature output, T0, b_i, g_i).
# Version 6 also adds ``zero``: the outputs' offsets fitted as an intercept (zero:
# intercept), which apply subtracts without a tare; a reader that ignored it would
# decouple offset forces.  Only models with one of these are version 6.
IMPORTED_FORMAT_VERSION = 6
ZERO_FORMAT_VERSION = IMPORTED_FORMAT_VERSION
READS_UP_TO = max(FORMAT_VERSION, OWN_FORMAT_VERSION, GAUGES_FORMAT_VERSION,
                  IMPORTED_FORMAT_VERSION)
METHODS = ("svr", "linear")


def model_to_dict(model: CouplingErrorModel) -> dict[str, Any]:
    """The model file's document, ``integrity`` digest included."""
    doc = _document(model)
    doc["integrity"] = _integrity(content_digest(doc))
    return doc


def _integrity(digest: str) -> dict[str, str]:
    return {"algorithm": "sha256", "digest": digest}


def _document(model: CouplingErrorModel) -> dict[str, Any]:
    """The model file's document without its ``integrity``."""
    doc = {
        "format": FORMAT,
        "format_version": IMPORTED_FORMAT_VERSION if model.imported or model.temperature
        else GAUGES_FORMAT_VERSION if model.projection is not None
        else OWN_FORMAT_VERSION if model.own else FORMAT_VERSION,
        "fsdecouple_version": __version__,
        "created": model.created,
        "sensor": model.settings.sensor,
        "settings": model.settings.to_dict(),
        "omega": {
            axis: {"k": float(model.k[a]), "inverse": float(1.0 / model.k[a]),
                   "r2": model.report.r2.get(axis) if model.report else None}
            for a, axis in enumerate(model.layout.labels)
        },
        "chi": {name: c.to_dict() for name, c in model.chi.items()},
        "method": model.method,
        "provenance": model.provenance,
        "report": model.report.to_dict() if model.report else {},
    }
    if model.own:
        doc["chi_own"] = {name: c.to_dict() for name, c in model.own.items()}
    if model.matrix is not None:
        doc["matrix"] = [[float(v) for v in row] for row in model.matrix]
    if model.projection is not None:
        doc["projection"] = [[float(v) for v in row] for row in model.projection]
    if model.temperature is not None:
        doc["temperature"] = model.temperature.to_dict(model.layout.outputs)
    if model.zero is not None:
        doc["zero"] = {"method": "intercept", "offsets": dict(zip(
            model.layout.outputs, (float(v) for v in model.zero), strict=True))}
        doc["format_version"] = ZERO_FORMAT_VERSION
    return doc


def save_model(model: CouplingErrorModel, path: str | Path, *, force: bool = True) -> None:
    """Write the model file atomically (sorted keys, no NaN).

    The text is ``json.dumps(model_to_dict(model), indent=1, sort_keys=True,
    allow_nan=False)`` plus a newline, written with its digest's canonical text in one
    pass (:mod:`fsdecouple.core.modeljson`).
    """
    doc = _document(model)
    canonical, indented = dump_forms(doc, leave_out=_NOT_DIGESTED)
    indented.update(dump_forms({"integrity": _integrity(_sha256(canonical))}, ())[1])
    text = join_indented(indented)
    with atomic_write(path, force=force) as fh:
        fh.write(text + "\n")


_NOT_DIGESTED = ("integrity", "created")


def content_digest(doc: dict[str, Any]) -> str:
    """SHA-256 of the canonical JSON of everything but ``integrity`` and ``created``.

    Leaving out the creation time makes refits of the same data byte-identical
    in everything but that one field.
    """
    body = {k: v for k, v in doc.items() if k not in _NOT_DIGESTED}
    return _sha256(json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=False))


def _sha256(canonical: str) -> str:
    return hashlib.sha256(canonical.encode("utf-8")).hexdigest()


def model_from_dict(doc: Any, source: str = "model") -> CouplingErrorModel:
    """The model of a model file's document, verified as :func:`load_model` verifies it."""
    return _model_from_dict(doc, source)


def _model_from_dict(doc: Any, source: str, computed: str | None = None) -> CouplingErrorModel:
    """``computed``: :func:`content_digest` of ``doc`` when the caller has it already."""
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise ModelFileError(f"{source}: not an fsdecouple model file (format is not '{FORMAT}')")
    version = doc.get("format_version")
    if not isinstance(version, int) or isinstance(version, bool):
        raise ModelFileError(
            f"{source}: format_version is missing or not a whole number ({version!r})"
        )
    if version < 1:
        raise ModelFileError(f"{source}: format_version {version} is unknown (versions start at 1)")
    if version > max(FORMAT_VERSION, READS_UP_TO):
        raise ModelFileError(
            f"{source}: format_version {version} was written by a newer fsdecouple "
            f"({doc.get('fsdecouple_version', '?')}); this one reads up to "
            f"{max(FORMAT_VERSION, READS_UP_TO)}"
        )
    integrity = doc.get("integrity")
    digest = integrity.get("digest") if isinstance(integrity, dict) else None
    if not isinstance(digest, str):
        raise ModelFileError(
            f"{source}: has no integrity digest, so it cannot be trusted (written by hand "
            "or by another tool?); refit the model"
        )
    try:
        expected = content_digest(doc) if computed is None else computed
    except (TypeError, ValueError) as err:  # NaN, inf or non-JSON values in a dict
        raise ModelFileError(f"{source}: malformed model file ({err})") from None
    if digest != expected:
        raise ModelFileError(
            f"{source}: integrity check failed: the content does not match its SHA-256 "
            "digest (edited by hand or corrupted); refit the model"
        )
    try:
        settings = settings_from_dict(_settings_yaml_form(doc["settings"]), f"{source}: settings")
        layout = settings.layout
        if version < 3 and not layout.is_default:
            raise ModelFileError(f"{source}: malformed model file (components in a version "
                                 f"{version} file)")
        k = np.array([float(doc["omega"][a]["k"]) for a in layout.labels])
        chi = {}
        imported = version >= IMPORTED_FORMAT_VERSION and doc.get("method") == "linear" \
            and doc.get("chi") == {}
        for name, pair in [] if imported else zip(layout.chi_names, layout.pairs, strict=True):
            if name not in doc["chi"]:
                raise ModelFileError(f"{source}: malformed model file (chi '{name}' is missing)")
            try:
                chi[name] = Chi.from_dict(name, doc["chi"][name],
                                          None if layout.is_default else pair)
            except (KeyError, TypeError, ValueError) as err:
                raise ModelFileError(
                    f"{source}: malformed model file (chi '{name}': {err})"
                ) from None
        own = _own_chis(doc.get("chi_own", {}), layout, version, source)
        projection = _projection(doc, layout, version, source, imported)
        temperature = _temperature(doc, layout, version, source)
        zero = _zero(doc, layout, version, source)
    except (KeyError, TypeError, ValueError) as err:
        raise ModelFileError(f"{source}: malformed model file ({type(err).__name__}: {err})") from None
    labels = settings.layout.labels
    bad = [a for a, v in zip(labels, k, strict=True) if not (np.isfinite(v) and v != 0.0)]
    if bad:
        raise ModelFileError(
            f"{source}: omega {bad[0]}: slope k = {float(k[labels.index(bad[0])])!r}, expected a finite "
            "non-zero number"
        )
    report = doc.get("report")
    _check_report(report, source, () if imported else labels, settings.full_scale)
    method, matrix = _method(doc, len(k), source, layout.m)
    if imported and not np.array_equal(matrix, projection):
        raise ModelFileError(f"{source}: malformed model file (an imported model's projection is "
                             "its matrix)")
    model = CouplingErrorModel(
        settings, k, chi, FitReport.from_dict(report), _provenance(doc, source),
        doc.get("created", ""), method, matrix, own, projection, temperature, zero,
    )
    _check_slopes(model, source)
    _check_tables(model, source)
    _check_intervals(model, source)
    return model


def _provenance(doc: dict, source: str) -> dict:
    """The file's ``provenance``, or one line saying what in it is not what fit writes (a
    list in its place gave tracebacks in show, apply and report)."""
    prov = doc.get("provenance", {})
    bad = _provenance_problem(prov)
    if bad is not None:
        raise ModelFileError(f"{source}: malformed model file ({bad} is not as fit writes it)")
    return prov


def _provenance_problem(prov: Any) -> str | None:
    """The first part of ``prov`` not shaped as fit writes it, or None."""
    if not isinstance(prov, dict):
        return "provenance"
    shapes = {"files": list, "libraries": dict, "excluded": list, "ati": dict, "zero": str}
    for key, kind in shapes.items():
        if key in prov and not isinstance(prov[key], kind):
            return f"provenance.{key}"
    if not all(isinstance(f, dict) and isinstance(f.get("path"), str)
               and isinstance(f.get("sha256"), str) for f in prov.get("files", [])):
        return "provenance.files"
    if not all(isinstance(x, str) for x in prov.get("excluded", [])):
        return "provenance.excluded"
    return None


# the start of the warning fit leaves when it leaves the certificate data out
LEFT_OUT = "no certificate data and no intervals"


def why_no_certificate(model) -> str:
    """Why a model has no certificate data, for the commands that need them: its fit left
    them out (its warning says why: refitting the same data would not help), or it was
    fitted by an older fsdecouple or without the held-out verdict."""
    said = next((w for w in getattr(model, "warnings", None) or [] if w.startswith(LEFT_OUT)),
                None)
    if said:
        return f"its fit left them out: {said.removeprefix(LEFT_OUT).lstrip(' (')}"
    return "fitted by an older fsdecouple, or without the held-out verdict; refit it"


def unloadable_certificate(model: CouplingErrorModel) -> str | None:
    """Why this model's certificate data would be refused when its file loads, or None:
    ``fit`` asks before it writes, so it never writes a file its reader refuses."""
    cert = model.report.certificate if model.report is not None else None
    if not cert:
        return None
    problem = _certificate_problem(cert, model.layout.labels, model.settings.full_scale)
    if problem:
        return problem
    try:
        check_interval_data(cert["interval"], model.layout.labels, model)
    except InputError as err:
        return getattr(err, "detail", str(err))  # without the reader's "damaged; refit"
    return None


def _check_intervals(model: CouplingErrorModel, source: str) -> None:
    """The interval data beyond the scores (issue 33: refused when the file loads, not
    when a log is half read), as :func:`fsdecouple.core.interval_data.check_interval_data`
    checks them against the model they belong to (its calibrated loads, k, full scale)."""
    cert = model.report.certificate if model.report is not None else None
    if not cert or not cert.get("interval"):
        return
    try:
        check_interval_data(cert["interval"], model.layout.labels, model)
    except InputError as err:
        raise ModelFileError(f"{source}: {err}") from None


def _zero(doc: dict, layout, version: int, source: str) -> np.ndarray | None:
    """The fitted offsets of a version-6 file (zero: intercept), one finite number per output."""
    if "zero" not in doc:
        return None
    raw = doc["zero"]
    offsets = raw.get("offsets") if isinstance(raw, dict) else None
    if version < ZERO_FORMAT_VERSION or not isinstance(offsets, dict) \
            or set(offsets) != set(layout.outputs):
        raise ModelFileError(f"{source}: malformed model file (zero: expected the offsets of "
                             f"outputs {', '.join(layout.outputs)}, format version "
                             f"{ZERO_FORMAT_VERSION})")
    z = np.array([offsets[c] for c in layout.outputs], dtype=float)
    if not np.isfinite(z).all():
        raise ModelFileError(f"{source}: malformed model file (zero: offsets must be finite)")
    return z


def _temperature(doc: dict, layout, version: int, source: str):
    """The temperature terms of a version-6 file, or None."""
    raw = doc.get("temperature")
    if raw is None:
        return None
    if version < IMPORTED_FORMAT_VERSION:
        raise ModelFileError(f"{source}: malformed model file (temperature in a version {version} "
                             "file)")
    try:
        return TemperatureTerms.from_dict(raw, layout.outputs)
    except (KeyError, TypeError, ValueError, AttributeError) as err:
        raise ModelFileError(f"{source}: malformed model file (temperature: {err})") from None


def _projection(doc: dict, layout, version: int, source: str, imported: bool = False
                ) -> np.ndarray | None:
    """P (N x M) of a version-5 file whose settings name M > N outputs, or of an imported
    model (version 6, P = its matrix); None otherwise."""
    if imported:
        if "projection" not in doc:
            raise ModelFileError(f"{source}: malformed model file (an imported model needs its "
                                 "projection)")
    elif not layout.overdetermined:
        if "projection" in doc:
            raise ModelFileError(f"{source}: malformed model file (a projection, but one output "
                                 "per component)")
        return None
    if version < GAUGES_FORMAT_VERSION or "projection" not in doc:
        raise ModelFileError(f"{source}: malformed model file ({layout.m} outputs for {layout.n} "
                             f"components need a projection, format version {GAUGES_FORMAT_VERSION})")
    p = np.array(doc["projection"], dtype=float)
    if p.shape != (layout.n, layout.m) or not np.isfinite(p).all():
        raise ModelFileError(f"{source}: malformed model file (projection: expected a finite "
                             f"{layout.n}x{layout.m} matrix)")
    return p


def _own_chis(raw: Any, layout, version: int, source: str) -> dict[str, Chi]:
    """The own-load chi_aa of a version-4 file (``chi_own``), keyed ``"fx:fx"``."""
    if not raw:
        return {}
    if version < OWN_FORMAT_VERSION or not isinstance(raw, dict):
        raise ModelFileError(f"{source}: malformed model file (chi_own in a version {version} "
                             "file)" if version < OWN_FORMAT_VERSION else
                             f"{source}: malformed model file (chi_own is not a mapping)")
    own = {}
    for name, d in raw.items():
        try:
            a, b = layout.pair(name)
            if a != b:
                raise ValueError("not an own-load chi (output and input differ)")
            own[name] = Chi.from_dict(name, d, (a, a))
        except (KeyError, TypeError, ValueError) as err:
            raise ModelFileError(
                f"{source}: malformed model file (chi_own '{name}': {err})") from None
    return own


# A slope's full-scale output |k_b| F_FS,b and the prime-voltage span the chi were
# trained on (input_range) come from the same sweeps: within a factor of ~10 in any
# fitted model.  Beyond this factor either way the slope cannot be the fit's.
SLOPE_SPAN_FACTOR = 1e6


def _check_slopes(model: CouplingErrorModel, source: str) -> None:
    """Each slope k agrees with the voltage span the model was calibrated on.

    A digest-valid file with k = 1e300 would otherwise decouple every force to 0.
    """
    fs_out, unit = model.full_scale_output, model.settings.output_unit
    for b, axis in enumerate(model.layout.labels):
        lo, hi = model.calibrated_range[b]
        span = hi - lo
        if not span > 0:
            continue  # nothing to compare with
        ratio = fs_out[b] / span
        if not (1 / SLOPE_SPAN_FACTOR <= ratio <= SLOPE_SPAN_FACTOR):
            raise ModelFileError(
                f"{source}: omega {axis}: slope k = {float(model.k[b])!r} puts full scale at "
                f"{fs_out[b]:.3g} {unit}, but the calibration spanned {span:.3g} {unit}; "
                "the slope is not the fit's (edited?), refit the model"
            )


def _check_tables(model: CouplingErrorModel, source: str) -> None:
    """Each table the fast path would use agrees with its own kernel sum (spot checks).

    The digest proves the file is as written, not that its tables are right: a
    table that disagrees beyond the gate the fast path trusts
    (:func:`fsdecouple.core.decouple.usable`) is refused, never applied silently.
    """
    fs_out = model.full_scale_output
    for c in [*model.chi.values(), *model.own.values()]:
        gate = MAX_SURROGATE_ERROR * fs_out[c.output_axis]
        if not usable(c.surrogate, fs_out[c.output_axis]):
            continue  # the fast path leaves it to the exact kernel sum anyway
        err, x = spot_check(c, c.surrogate)
        if not err <= gate:
            raise ModelFileError(
                f"{source}: chi '{c.name}': its surrogate table differs from its own kernel "
                f"sum by {err:.3g} at u = {x:.6g} (the fast path trusts {gate:.3g}); "
                "the model is inconsistent, refit it"
            )


def _method(doc: dict[str, Any], n: int, source: str, m: int | None = None
            ) -> tuple[str, np.ndarray | None]:
    """The decoupling method and, for ``linear``, its N x M finite calibration matrix."""
    m = n if m is None else m
    method = doc.get("method", "svr")
    if method not in METHODS:
        raise ModelFileError(f"{source}: malformed model file (method {method!r}, expected "
                             f"{' or '.join(METHODS)})")
    if method == "svr" and "matrix" not in doc:  # svr files fitted before it was kept have none
        return method, None
    try:
        matrix = np.array(doc["matrix"], dtype=float)
    except (KeyError, TypeError, ValueError):
        matrix = None
    if matrix is None or matrix.shape != (n, m) or not np.isfinite(matrix).all():
        raise ModelFileError(f"{source}: malformed model file (an svr model's matrix, kept for "
                             f"validate, must be a finite {n}x{m} one)" if method == "svr" else
                             f"{source}: malformed model file (a linear model needs a finite "
                             f"{n}x{m} matrix)")
    return method, matrix


def _check_report(report: Any, source: str, labels, full_scale) -> None:
    """The fit figures ``show`` prints: per-axis numbers and a list of warnings."""
    def number(v):
        return isinstance(v, int | float) and not isinstance(v, bool)

    if not isinstance(report, dict):
        raise ModelFileError(f"{source}: malformed model file (report is not a mapping)")
    for key in ("r2", "n_points", "gamma_before", "gamma_after"):
        table = report.get(key)
        if not (isinstance(table, dict) and all(number(table.get(a)) for a in labels)):
            raise ModelFileError(
                f"{source}: malformed model file (report: {key} needs a number per axis)"
            )
    warnings = report.get("warnings", [])
    if not (isinstance(warnings, list) and all(isinstance(w, str) for w in warnings)):
        raise ModelFileError(f"{source}: malformed model file (report: warnings is not a list of text)")
    problem = None if report.get("certificate") is None else \
        _certificate_problem(report["certificate"], labels, full_scale)
    if problem:
        raise ModelFileError(f"{source}: malformed model file (report: {problem}); refit it")


def _certificate_problem(cert: Any, labels, full_scale) -> str | None:
    """What is wrong with the step data compare and certificate read and the scores apply
    --interval reads (evaluation.budget), or None.

    The digest proves the file is as written, not that its numbers can be: every number a
    result depends on is checked as the chi tables are (negative or unsorted scores gave
    intervals with lo > hi, sigma = 0 intervals of zero width, U = 0 an E_n of 0/0).
    """
    try:
        for a, fs in zip(labels, full_scale, strict=True):
            st = cert["steps"][a]
            n = len(st["load"])
            if not (numbers(st["load"]) and numbers(st["U"], n) and numbers(st["model_error"], n)
                    and isinstance(st["outputs"], list) and len(st["outputs"]) == n
                    and all(numbers(o, len(labels)) for o in st["outputs"])):
                return "certificate needs steps and interval scores per component"
            limit = MAX_FULL_SCALES * fs
            for key, low in (("U", "positive"), ("model_error", "non-negative")):
                bad = [x for x in st[key] if not (0.0 < x <= limit if low == "positive"
                                                  else 0.0 <= x <= limit)]
                if bad:
                    return (f"certificate: {a}: {key} = {bad[0]!r}; expected a {low} number of at "
                            f"most {MAX_FULL_SCALES:g} full scales ({limit:g})")
            c = cert["interval"]["components"][a]
            own = c["scores"] if c["scores"] is not None else cert["interval"]["scores"]
            if not (numbers([c["sigma"]]) and numbers(own) and own):
                return "certificate needs steps and interval scores per component"
            sigma = c["sigma"]
            if not 0.0 < sigma <= limit:
                return (f"interval: {a}: sigma = {sigma!r}; expected a positive number of at "
                        f"most {MAX_FULL_SCALES:g} full scales ({limit:g})")
            unsorted = [y for x, y in zip(own[:-1], own[1:], strict=True) if y < x]
            if own[0] < 0.0 or unsorted:
                bad = own[0] if own[0] < 0.0 else unsorted[0]
                return (f"interval: {a}: held-out score {bad!r} out of place; expected "
                        "non-negative scores in ascending order")
            if not own[-1] > 0.0:  # held-out errors of noisy readings: never all exact
                return (f"interval: {a}: held-out scores all {own[-1]!r}; expected the held-out "
                        "errors' sizes, not all zero (intervals of zero width)")
            if own[-1] * sigma > limit:
                return (f"interval: {a}: held-out score {own[-1]!r} times sigma {sigma!r} is "
                        f"more than {MAX_FULL_SCALES:g} full scales ({limit:g})")
            # pooled scores are errors over sigma, ~1 or more; a component's own are raw
            square = float(np.mean(np.square(own))) if c["scores"] is None else math.inf
            if square < MIN_MEAN_SQUARE:
                return (f"interval: {a}: held-out scores' mean square {square!r}; expected at "
                        f"least {MIN_MEAN_SQUARE:g} (scores are errors over their noise)")
    except (KeyError, TypeError):
        return "certificate needs steps and interval scores per component"
    return None


def _settings_yaml_form(d: dict[str, Any]) -> dict[str, Any]:
    """Settings.to_dict() output back into the YAML config's shape."""
    d = dict(d)
    d.setdefault("extrapolation", LEGACY_EXTRAPOLATION)  # files from before the option
    svr = dict(d.pop("svr"))
    return {**d, "svr": svr}


class _NonFinite(ValueError):
    pass


class _DuplicateKey(ValueError):
    pass


def _unique_keys(pairs):
    # the digest covers the parsed document, so a second, shadowed key would
    # pass it while showing a reader a value the model does not use
    doc = dict(pairs)
    if len(doc) != len(pairs):
        seen = set()
        raise _DuplicateKey(next(k for k, _ in pairs if k in seen or seen.add(k)))
    return doc


def _finite_float(text: str) -> float:
    value = float(text)
    if not np.isfinite(value):  # 1e999 parses to inf
        raise _NonFinite(text)
    return value


def _refuse_constant(name: str):
    # json accepts NaN/Infinity, which the writer never produces (allow_nan=False)
    raise _NonFinite(name)


def load_model(path: str | Path) -> CouplingErrorModel:
    """Read and verify a model file."""
    path = Path(path)
    try:
        # a BOM from a Windows editor is not content
        text = read_bounded(path, MODEL_LIMIT, "a model file", ModelFileError).decode("utf-8-sig")
    except FileNotFoundError:
        raise ModelFileError(f"{path}: model file not found") from None
    except (OSError, UnicodeDecodeError) as err:
        raise ModelFileError(f"{path}: cannot read model file ({err})") from None
    doc, computed = _parse(text, path)
    return _model_from_dict(doc, str(path), computed)


def _parse(text: str, path: Path) -> tuple[Any, str | None]:
    """The document of a model file's text, every number finite, and its digest.

    The decoder parses floats natively; one canonical dump with ``allow_nan=False``
    then both refuses a number that overflowed to infinity (``1e999``) and gives
    :func:`content_digest`, so a model file costs one parse and one dump.  Any failure
    parses the text again as :func:`_parse_checked` does, which names the first bad
    value or position exactly as it always has: the fast path never decides a message.
    """
    try:
        doc = json.loads(text, parse_constant=_refuse_constant, object_pairs_hook=_unique_keys)
        if isinstance(doc, dict):
            _dump_finite([doc.get("created"), doc.get("integrity")])
            return doc, content_digest(doc)
        _dump_finite(doc)
        return doc, None
    except (ValueError, RecursionError):  # JSONDecodeError, _NonFinite, _DuplicateKey too
        pass
    return _parse_checked(text, path), None


def _dump_finite(value: Any) -> None:
    """Raise ValueError if ``value`` holds a NaN or an infinity (as json.dumps does)."""
    json.dumps(value, allow_nan=False)


def _parse_checked(text: str, path: Path) -> Any:
    """Parse with a check per float: the slow path that names the first bad value."""
    try:
        return json.loads(
            text, parse_constant=_refuse_constant, parse_float=_finite_float,
            object_pairs_hook=_unique_keys,
        )
    except json.JSONDecodeError as err:
        raise ModelFileError(
            f"{path}, row {err.lineno}, column {err.colno}: not valid JSON (truncated?)"
        ) from None
    except _DuplicateKey as err:
        raise ModelFileError(
            f"{path}: key '{excerpt(err.args[0])}' appears twice in one object (edited by hand?); "
            "json would keep the last one silently"
        ) from None
    except _NonFinite as err:
        raise ModelFileError(
            f"{path}: holds {excerpt(repr(err.args[0]))}; NaN and infinity are not allowed in a model file"
        ) from None
    except RecursionError:
        raise ModelFileError(f"{path}: not a model file (JSON too deeply nested)") from None
    except ValueError as err:  # e.g. an integer of more than 4300 digits
        raise ModelFileError(f"{path}: not a model file ({excerpt(err)})") from None
