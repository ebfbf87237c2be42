"""Which columns of a log are the model's outputs, and a temperature given instead of read.

The outputs are read by the config's column names.  A model with temperature terms
(:mod:`fsdecouple.core.temperature`) reads its temperature as one of its outputs (an
ATI thermistor).  A log without that column is refused in one line, unless
``apply --temperature VALUE`` gives the reading for every row: then the column is not
read and a constant one is put in its place.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable, Iterator

import numpy as np

from ..data.ati_model import check_log_gauges
from ..data.csv_text import HEADER_ROW
from ..errors import InputError, where


def log_outputs(model, settings, header, path, temperature: float | None = None
                ) -> tuple[dict[str, str], Callable[[Iterable], Iterator]]:
    """``({output: log column} to read, jobs -> jobs)``: the second adds the temperature
    column to each block when ``temperature`` is given, else passes the jobs through.

    Gauge columns beyond an imported factory matrix's NumGages are refused
    (:func:`fsdecouple.data.ati_model.check_log_gauges`)."""
    check_log_gauges(model, header, path)  # an imported factory matrix: NumGages columns
    layout = model.layout
    read = {c: settings.columns[c] for c in layout.outputs}
    terms = model.temperature
    if temperature is not None and terms is None:
        raise InputError("--temperature: the model has no temperature terms; nothing would use it")
    if terms is None:
        return read, iter
    if terms.external:  # a fitted model: the temperature column after the outputs
        return _fitted_temperature(model, settings, header, path, read, temperature)
    t_name = read[layout.outputs[terms.channel]]
    if temperature is None:
        if t_name not in header:
            raise InputError(f"{where(path, HEADER_ROW)}: no column '{t_name}', the temperature "
                             "the model corrects for (core/temperature.py); give its reading for "
                             "every row with --temperature VALUE")
        return read, iter
    if t_name in header:
        raise InputError(f"{where(path, HEADER_ROW, t_name)}: --temperature: the log has this "
                         "column, which it would replace; give one or the other")
    del read[layout.outputs[terms.channel]]
    value = float(temperature)

    def with_column(job):
        def add() -> object:
            block = job()
            return dataclasses.replace(block, u=np.insert(block.u, terms.channel, value, axis=1))
        return add

    return read, lambda jobs: (with_column(job) for job in jobs)


def _fitted_temperature(model, settings, header, path, read, temperature):
    """A fitted model's temperature (``columns: {temperature: ...}``, in the config's unit,
    read as degC): the log's column, or ``--temperature VALUE`` for every row, appended
    after the outputs as the plan's one more input."""
    from ..temperature_units import DEFAULT_TEMPERATURE, column, to_celsius, unit

    given = settings if column(settings) is not None else model.settings
    name, unit = column(given) or DEFAULT_TEMPERATURE, unit(given)
    if temperature is None:
        if name is None or name not in header:
            shown = f"no column '{name}'" if name is not None else "no temperature column mapped"
            raise InputError(f"{where(path, HEADER_ROW)}: {shown}, the temperature the model "
                             "corrects for (fitted with temperature terms); map it as columns: "
                             "{temperature: ...} or give its reading for every row with "
                             "--temperature VALUE")
        read = {**read, "temperature": name}

        def converted(job):
            def run() -> object:
                block = job()
                u = block.u.copy()
                u[:, -1] = to_celsius(u[:, -1], unit)
                return dataclasses.replace(block, u=u)
            return run

        return read, lambda jobs: (converted(job) for job in jobs)
    if name is not None and name in header:
        raise InputError(f"{where(path, HEADER_ROW, name)}: --temperature: the log has this "
                         "column, which it would replace; give one or the other")
    value = float(to_celsius(float(temperature), unit))

    def with_column(job):
        def add() -> object:
            block = job()
            return dataclasses.replace(block, u=np.column_stack([block.u, np.full(len(block.u), value)]))
        return add

    return read, lambda jobs: (with_column(job) for job in jobs)


def input_names(model) -> tuple[str, ...]:
    """The plan's raw inputs: the outputs, then ``temperature`` for a fitted model's."""
    extra = ("temperature",) if model.n_inputs > model.n_outputs else ()
    return (*model.layout.outputs, *extra)


def input_scale(model, settings) -> np.ndarray:
    """The config's ``scale:`` per input (1 for a fitted model's temperature, in degC)."""
    return np.array([settings.scale.get(c, 1.0) for c in input_names(model)])


def row_forces(model, u, raw, offsets, empty, converged, compiled) -> np.ndarray:
    """Forces of a block's rows: eq. (11) on ``u`` (raw less the zero), or for a model with
    temperature terms its plan on the raw inputs, their temperature and the zero
    (:class:`fsdecouple.core.plan.TemperatureCorrection`).  Empty rows compute on zeros."""
    terms = model.temperature
    if terms is None:
        return model.decouple(np.where(empty[:, None], 0.0, u) if empty.any() else u,
                              workers=1, converged=converged, compiled=compiled)
    x = np.where(empty[:, None], 0.0, raw) if empty.any() else raw
    return model.decouple(x[:, :model.n_outputs], workers=1, converged=converged,
                          compiled=compiled, temperature=x[:, terms.channel],
                          zero=offsets if np.any(offsets) else None)


def beyond_temperatures(model, raw) -> np.ndarray:
    """Rows (n,) whose temperature is outside the calibrated span (apply's 'extrapolated')."""
    terms = model.temperature
    if terms is None:
        return np.zeros(len(raw), dtype=bool)
    return terms.outside(raw[:, terms.channel])


def limit_bounds(settings, model) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) per input; +-inf where no limit is given (never saturated; a temperature)."""
    limits = settings.limits or model.settings.limits
    outputs = input_names(model)
    lo = np.array([limits.get(c, (-np.inf, np.inf))[0] for c in outputs])
    hi = np.array([limits.get(c, (-np.inf, np.inf))[1] for c in outputs])
    return lo, hi
