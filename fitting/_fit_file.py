"""A stack file read for a fit: its fitting words become :class:`~fitting.Parameter` objects.

A stack file may write fitting words beside a value (schema: :mod:`layerstack_jax.io`, "Free
parameters")::

    thickness_nm = { value = 30000, free = true, min = 0, max = 1e5 }
    alpha_per_nm = { table = "alpha.csv", free = true, basis = 8 }
    thickness_nm = { value = [115000, 480000], free = true, per_sample = true, known = [true, false] }

The stack file's reader (:func:`layerstack_jax.io.stack_from_dict`) takes the value and returns
the words unread, one :class:`~layerstack_jax.io.Annotation` per annotated value. This module
owns their meaning: it checks each word (messages name the file, the table and the key) and
makes a :class:`Parameter` of each value marked ``free = true`` (:func:`parameter_of`);
:func:`load_fit_file` reads a file once for a fit.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import NamedTuple, Optional, Sequence

import numpy as np

from layerstack_jax import LayerstackError, Stack
from layerstack_jax.io import (
    Annotation,
    InstrumentSettings,
    instrument_settings,
    is_number,
    read_toml,
    stack_from_dict,
)

from ._parameters import Parameter

__all__ = ["parameter_of", "parameters_from_annotations", "FitFile", "load_fit_file", "load_fit_parameters"]


def _flag(a: Annotation, word: str) -> bool:
    value = a.words.get(word, False)
    if not isinstance(value, bool):
        raise a.where.error(f"{word} must be true or false, got {value!r}", a.key)
    return value


def _bounds(a: Annotation) -> tuple[Optional[float], Optional[float]]:
    """``min``/``max`` as written (None: not given), checked."""
    bounds = {}
    for word in ("min", "max"):
        if word in a.words:
            v = a.words[word]
            if not is_number(v) or math.isnan(float(v)):
                raise a.where.error(f"{word} must be a number, got {v!r}", a.key)
            bounds[word] = float(v)
    lo, hi = bounds.get("min"), bounds.get("max")
    if lo is not None and hi is not None and not lo < hi:
        raise a.where.error(f"bounds inverted: min {lo:g} must be < max {hi:g}", a.key)
    return lo, hi


def _within_range(a: Annotation, lo: Optional[float], hi: Optional[float]) -> tuple:
    """Bounds of a value with a physical range (:attr:`Annotation.value_range`): the range
    where a bound is not given; given bounds must lie in it."""
    if a.value_range is None:
        return lo, hi
    lower, upper = a.value_range
    lo, hi = (lower if lo is None else lo), (upper if hi is None else hi)
    if (lower is not None and lo < lower) or (upper is not None and hi > upper):
        # only a dispersion model's coefficients have a physical range, and they are written under n
        raise a.where.error(f"{a.key}: bounds [{lo:g}, {hi:g}] outside the range [{lower:g}, {upper:g}]", "n")
    return lo, hi


def _basis(a: Annotation):
    basis = a.words.get("basis")
    if basis is not None:
        if not a.spectral:
            raise a.where.error("basis is for spectra (alpha_per_nm, rho_g) only", a.key)
        if not (basis == "free" or (isinstance(basis, int) and not isinstance(basis, bool) and basis >= 1)):
            raise a.where.error(f"basis must be a number of B-spline functions >= 1 or \"free\", got {basis!r}", a.key)
    return basis


def _per_sample_values(a: Annotation) -> tuple:
    """``(values, known)`` of a per-sample number written as a list (``value = [a, b, ...]``,
    optional ``known = [true, false, ...]``), checked; ``values`` None for a single number."""
    known, values = a.words.get("known"), a.value
    if values is None:
        if known is not None:
            raise a.where.error("known = [...] marks samples of a per-sample value: write value = [one number per "
                                "sample] with the known samples' values", a.key)
        return None, None
    if not a.words.get("per_sample", False):
        raise a.where.error(f"value = [...] gives one value per sample: add per_sample = true (got {values!r})", a.key)
    if not values or not all(is_number(v) and math.isfinite(float(v)) for v in values):
        raise a.where.error(f"value must be a number, or a list of numbers (one per sample), got {values!r}", a.key)
    values = tuple(float(v) for v in values)
    if known is None:
        return values, None
    if not (isinstance(known, list) and all(isinstance(k, bool) for k in known)):
        raise a.where.error(f"known must be a list of true/false, one per sample, got {known!r}", a.key)
    if len(known) != len(values):
        raise a.where.error(f"known has {len(known)} entries for {len(values)} values (one per sample)", a.key)
    if all(known):
        raise a.where.error("every sample's value is known: nothing is left to fit (drop free, or mark a sample "
                            "false)", a.key)
    return values, tuple(known)


def parameter_of(a: Annotation) -> Optional[Parameter]:
    """The :class:`Parameter` of one annotated value of a stack file, or None when it is not
    marked ``free = true``. Every word is checked (a :class:`LayerstackError` names the file,
    the table, the key and what is wrong); bounds are in the value's file unit (nm, 1/nm,
    fraction), None where the file gives none (the kind's default applies)."""
    is_free = _flag(a, "free")
    lo, hi = _bounds(a)
    basis = _basis(a)
    per_sample = _flag(a, "per_sample")
    smooth = a.words.get("smoothness", 0.0)
    if not is_number(smooth) or smooth < 0:
        raise a.where.error(f"smoothness must be a number >= 0, got {smooth!r}", a.key)
    given = [w for w in ("min", "max", "basis", "per_sample", "known", "smoothness") if w in a.words]
    if given and not is_free:
        raise a.where.error(f"{', '.join(given)} given but free is not true", a.key)
    if "known" in a.words and a.spectral:
        raise a.where.error("known is for per-sample numbers (thickness_nm, n, k)", a.key)
    values, known = _per_sample_values(a)
    if not is_free:
        return None
    lo, hi = _within_range(a, lo, hi)
    return Parameter(path=tuple(a.path), kind=a.kind, name=a.name, lower=lo, upper=hi, basis=basis,
                     per_sample=per_sample, smoothness=float(smooth),
                     # a per-sample number written as a list: each sample's start, the known ones fixed
                     value=None if values is None else np.asarray(values, float),
                     fixed=None if known is None else np.asarray(known, bool))


def parameters_from_annotations(annotations: Sequence[Annotation], source: str = "") -> list[Parameter]:
    """The :class:`Parameter` of each value a stack file marks free (:func:`parameter_of`), in
    the file's order. ``annotations``: as collected by ``layerstack_jax.io.stack_from_dict(d,
    annotations=[])``; ``source``: the file, for the message when none is free."""
    params = [p for p in map(parameter_of, annotations) if p is not None]
    if not params:
        raise LayerstackError(f"{source or 'stack file'}: no free parameter: mark some with e.g. "
                              "thickness_nm = { value = 30000, free = true }")
    return params


class FitFile(NamedTuple):
    """A stack file read for a fit (:func:`load_fit_file`): the stack, its free parameters and
    its ``[instrument]`` settings."""

    stack: Stack
    parameters: list
    instrument: InstrumentSettings


def load_fit_file(path) -> FitFile:
    """A stack file with free parameters, read once: the stack, ``[Parameter]`` of the values it
    marks free (schema: :mod:`layerstack_jax.io`, "Free parameters") and its ``[instrument]``
    settings (:func:`layerstack_jax.io.instrument_settings`)."""
    path = Path(path)
    raw = read_toml(path)
    annotations: list = []
    stack = stack_from_dict(raw, path.parent, source=str(path), annotations=annotations)
    settings = instrument_settings(raw, str(path))
    return FitFile(stack, parameters_from_annotations(annotations, str(path)), settings)


def load_fit_parameters(path) -> tuple[Stack, list[Parameter]]:
    """A stack file with free parameters → ``(stack, [Parameter])`` (:func:`load_fit_file`)."""
    f = load_fit_file(path)
    return f.stack, f.parameters
