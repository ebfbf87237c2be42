"""One fit: the model ``fsdecouple fit`` writes, as one Python call (``fsdecouple.fit``).

:func:`fit` does what the command does and the command only renders it: the
SVR settings chosen by held-out error (``tune``), the coupling error model
(:mod:`fsdecouple.fitting.fit`, Section 2.3), the gross errors flagged
(:mod:`fsdecouple.fitting.outliers`), the held-out verdict against the calibration
matrix (:mod:`fsdecouple.evaluation.verdict`), the least-squares matrix kept beside
the model, the method it decouples by, and the held-out data of the certificate and
of ``apply --interval`` (:mod:`fsdecouple.evaluation.budget`).

This module imports the fitting stack only when :func:`fit` runs: ``fsdecouple.fit``
is a public name, and loading a model must not pay for libsvm or pandas.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ..config import Settings
    from ..core.model import CouplingErrorModel
    from ..data.calibration import CalibrationSet
    from .tune import Grid

from ..schema import FIT_METHODS


def fit(calib: CalibrationSet | str | Path, settings: Settings | None = None, *,
        method: str | None = None, verdict: bool = True, tune: bool = False,
        tune_grid: Grid | str | None = None, workers: int | None = None,
        progress: Callable[[int, int], None] | None = None) -> CouplingErrorModel:
    """Fit the coupling error model as ``fsdecouple fit`` does; the model it writes.

    Parameters
    ----------
    calib : CalibrationSet or path
        The calibration (:func:`fsdecouple.load_calibration`), or a path to read it from.
    settings : Settings, optional
        The configuration (:func:`fsdecouple.load_config`); default: the one ``calib``
        was read with (:func:`fsdecouple.load_calibration`), else the built-in one.
    method : {'svr', 'linear', 'auto'}, optional
        What the model decouples by (``--method``): the coupling error model (eq. 11,
        the paper's), the least-squares calibration matrix, or whichever has the lower
        held-out figure of the verdict (worst gamma, eq. 12; on rig rows the worst
        component's RMS error).  Default: the config's ``method:``, else ``svr``.
    verdict : bool
        Judge the model on held-out points against the calibration matrix
        (``verdict=False`` is ``--no-verdict``).  When the protocol cannot run (e.g. a
        sweep with a single loaded point) the model comes back with a warning, unless
        ``auto`` needs it.
    tune : bool
        Choose gamma, C and epsilon by held-out error first (``--tune``); the grid and
        the choice go into ``model.report.tune``.
    tune_grid : Grid or str, optional
        The grid of ``tune`` (``--tune-grid``), e.g. ``"gamma=1,2,4;C=10,1000"``.
    workers : int, optional
        Threads training the SVRs, the model's and the verdict's at once (default: the
        cores; 1: one after the other).  The model does not depend on it.
    progress : callable, optional
        ``progress(done, total)``, called while tuning.

    Returns
    -------
    CouplingErrorModel
        With its report (verdict, tune, outliers, gamma after), the least-squares
        matrix, the method and the held-out data of ``apply --interval``.
    """
    from ..config import Settings
    from ..data.calibration import CalibrationSet, load_calibration
    from ..errors import InputError

    read_with = getattr(calib, "settings", None)
    if settings is not None and read_with is not None:
        _same_reading(read_with, settings)
    settings = settings or read_with or Settings()
    note = None
    if method is None and settings.method == "auto" and not verdict:
        # the config's auto (init writes it for poses) with the verdict turned off here:
        # the flag is the more specific, so the paper's method, said once
        method, note = "svr", ("the config's method auto chooses by the held-out verdict, "
                               "which is off: the model decouples by svr")
    method = method or settings.method or "svr"
    if method not in FIT_METHODS:
        raise InputError(f"method {method!r}: expected one of {', '.join(FIT_METHODS)}",
                         argument="method")
    if method == "auto" and not verdict:
        raise InputError("method auto chooses by the held-out verdict, which is off: turn it on",
                         argument="method")
    if method == "linear" and settings.refine:
        from ..core.model import LINEAR_NOT_REFINED
        raise InputError(f"refine {settings.refine}: {LINEAR_NOT_REFINED}")  # config or flag
    if method == "linear" and tune:  # the grid would be fitted, scored and thrown away
        raise InputError("tuning chooses the SVRs' gamma, C and epsilon, and a linear model has "
                         "none: leave tuning off, or fit the method svr or auto", argument="tune")
    if isinstance(tune_grid, str):
        from .tune import grid_option
        tune_grid = grid_option(tune, tune_grid)
    elif tune_grid is not None and not tune:
        raise InputError("a grid for tuning, but tuning is off: turn it on", argument="tune_grid",
                         remedy=("tune", ""))
    if not isinstance(calib, CalibrationSet):
        calib = load_calibration(calib, settings)
    if settings.zero is None and getattr(calib, "zero", None) == "fit" != settings.zero_method:
        settings = dataclasses.replace(settings, zero="fit")  # out-and-back sweeps (zero.py)
    from ..fitting import svr  # noqa: F401 (libsvm loads on this thread, before the pool: svr.py)
    from ..fitting.temperature import compensate
    from ..fitting.threads import single_threaded_libraries

    with single_threaded_libraries():  # the terms' least squares too (threads.py)
        calib, _ = compensate(calib, settings)  # outputs at T0 for every figure below (issue 31)
        model = _fit(calib, settings, method, verdict, tune, tune_grid, workers, progress)
    if note:
        model.report.warnings.append(note)
    return model


def _same_reading(read_with, settings) -> None:
    """Refuse fitting a set with settings that read its numbers otherwise than it was read
    (a gram-force set fitted in newtons): a ``fit(calib, other)`` that would be wrong in
    silence.  The keys are the certificate's (READING_KEYS) but the sensor's name and
    ``zero``, which fit may choose itself."""
    from ..errors import InputError
    from .certificate_doc import reading_differences

    differ = reading_differences(read_with, settings, skip=("sensor", "zero"))
    if differ:
        raise InputError(f"the calibration was read with other settings ({', '.join(differ)} "
                         "differ from these): fit it with the settings it was read with, or "
                         "read it again with these")


def _fit(calib, settings, method, verdict, tune, tune_grid, workers, progress):
    from ..core.metrics import interference_errors
    from ..core.modelfile import LEFT_OUT, unloadable_certificate
    from ..errors import InputError
    from ..fitting.fit import fit as establish
    from ..fitting.linear import fit_calibration_matrix
    from ..fitting.outliers import gross_errors
    from ..fitting.threads import thread_pool
    from .budget import certificate_data
    from .verdict import choose, heldout_verdict, summary, verdict_warning

    record = None
    configured = settings.svr
    if tune:
        from .tune import tune_settings
        settings, record = tune_settings(calib, settings, grid=tune_grid, workers=workers,
                                         progress=progress)
    cores = workers or os.cpu_count() or 1
    found, failed = None, None
    # the held-out rounds train beside the model (libsvm trains without the GIL), unless
    # one thread was asked for
    with thread_pool(1) as pool:
        pending = (pool.submit(heldout_verdict, calib, settings, workers=cores)
                   if verdict and cores > 1 else None)
        model = establish(calib, settings, workers=workers)
        try:
            if pending is not None:
                found = pending.result()
            elif verdict:
                found = heldout_verdict(calib, settings, workers=1)
        except InputError as err:
            failed = err
    model.report.tune = record
    if record is not None and record["chosen"] != 0 and not configured.table2:
        # the settings the user wrote were candidate 0, and tuning chose another: say so
        pick = record["candidates"][record["chosen"]]
        model.report.warnings.append(
            f"tuning replaced the configured SVR settings (C={configured.C:g}, epsilon="
            f"{configured.epsilon:g}, gamma={configured.gamma:g}: candidate 0) by gamma="
            f"{pick['gamma']:g} C={pick['C']:g} epsilon={pick['epsilon']:.3g} (full scale), "
            "clearly better on held-out points; fit without tuning keeps them")
    points, layout = calib.points, settings.layout
    if layout.overdetermined:  # M > N: each component's least-squares load v = P u (gauges.py)
        from ..fitting.gauges import projected
        points, layout = projected(points, model.projection, layout)
    outliers = gross_errors(points, model.k, settings.full_scale, layout)
    model.report.outliers = [dataclasses.asdict(o) for o in outliers]
    # the residual is on the output's own component (a joint row's other outputs too)
    model.report.warnings += [o.message(settings.units.load_of(layout.outputs.index(o.output)))
                              for o in outliers]
    if failed is not None:
        if method == "auto":
            raise InputError(f"method 'auto' needs a held-out verdict, which cannot run: {failed}",
                             argument="method") from None
        model.report.warnings.append(f"no held-out verdict: {failed}")
    chosen = choose(found, method) if found is not None else method
    # the least-squares matrix on the same calibration, kept by an svr model too, so
    # validate can set it beside the model (a linear model decouples by it)
    model.matrix = fit_calibration_matrix(calib.voltages, calib.forces).C
    if chosen == "linear":
        model.method = "linear"
        model.report.gamma_after = interference_errors(
            calib.points, model.decouple(calib.voltages, rotate=False), settings.full_scale,
            settings.layout, settings.units.loads or None)
    if found is not None:
        model.report.verdict = {**summary(found), "asked": method, "chosen": chosen}
        if not settings.layout.overdetermined:  # per prime output: none with M > N outputs
            model.report.certificate = certificate_data(calib, model,
                                                        *found["predictions"][chosen], found["trained"],
                                                        found["centred"][chosen])
            problem = unloadable_certificate(model)
            if problem:  # e.g. a calibration without reading noise: no file its reader refuses
                model.report.certificate = None
                model.report.warnings.append(
                    f"{LEFT_OUT} (the certificate, compare's E_n, apply's intervals): what they "
                    f"would hold cannot be calibrated here ({problem}); a calibration without "
                    "reading noise?")
        warning = verdict_warning(found, chosen)
        if warning:
            model.report.warnings.append(warning)
    return model


def fit_document(model: CouplingErrorModel, output: str | Path, checks: list,
                 advice: dict[str, Any]) -> dict[str, Any]:
    """``fit --json``: the model file's report without the certificate's step data (that is
    ``fsdecouple certificate``'s), the checks of Section 2.1 and the advice."""
    report = {k: v for k, v in model.report.to_dict().items() if k != "certificate"}
    return {"model": str(output), "method": model.method, **report,
            "k": model_slopes(model), "units": model_units(model, surrogate=True),
            "checks": [c.to_dict() for c in checks], "refine": model.settings.refine,
            "extrapolation": model.settings.extrapolation,
            "refine_advice": advice, "tune": model.report.tune}


def model_slopes(model: CouplingErrorModel) -> dict[str, float]:
    """Each component's slope k of eq. (2), by its name."""
    return {name: float(k) for name, k in zip(model.layout.labels, model.k, strict=True)}


def model_units(model: CouplingErrorModel, surrogate: bool = False) -> dict[str, Any]:
    """The units of a model's figures: ``load``, ``output``, and ``k``: each slope's (eq. 2)
    output per load (one load unit for forces, another for moments); with more gauges
    than loads k of the least-squares loads v = P u, a pure number.  ``surrogate``: and
    ``surrogate_max_error``'s, the chi's own (loads v where there are more gauges)."""
    units = model.settings.units
    projected = getattr(model, "projection", None) is not None
    out = {"load": units.load, "output": units.output,
           "k": {name: "" if projected else f"{units.output_of(a)}/{units.load_of(a)}"
                 for a, name in enumerate(model.layout.labels)}}
    if surrogate:
        out["surrogate_max_error"] = units.load if projected else units.output
    return out
