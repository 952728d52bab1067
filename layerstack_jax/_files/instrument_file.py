"""The ``[instrument]`` table of a stack file (schema: :mod:`layerstack_jax.io`, "The
instrument"): fields of the measurement geometries of a fit or a prediction — read
(:func:`instrument_settings`, :func:`load_instrument`) and applied to geometries
(:func:`instrument_geometry`, :func:`check_instrument_used`).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Mapping, NamedTuple, Optional

from .._base.validate import LayerstackError
from .annotations import ANNOTATION_KEYS, annotated
from .file_grammar import FileLocation, read_number, read_toml

__all__ = ["InstrumentSettings", "read_instrument_table", "instrument_settings", "load_instrument",
           "instrument_geometry", "check_instrument_used"]

#: keys of ``[instrument]`` that are not numbers: which layer a thickness spread applies to
_INSTRUMENT_STATIC = ("nonuniform_layer",)


class InstrumentSettings(NamedTuple):
    """The ``[instrument]`` table of a stack file (schema: :mod:`layerstack_jax.io`, "The
    instrument"): fields of the measurement geometries of a fit or a prediction.

    Attributes:
        values: field name → number, in the geometry field's unit (``angle_offset_deg`` in
            degrees, ``bandwidth_nm`` in nm, ``thickness_spread`` dimensionless …).
        static: field name → value of the non-numeric fields (``nonuniform_layer``: a layer's
            name or 0-based position).
        where: ``"<file>: [instrument]"`` for messages.
    """

    values: dict
    static: dict
    where: str


def read_instrument_table(source: str, table: Mapping, annotations: Optional[list], layer_names: list) -> InstrumentSettings:
    """Read an ``[instrument]`` table: each key a number or a free-parameter table (declared as
    ``("datasets", "all", key)``: one value shared by every dataset whose geometry has the field)."""
    where = FileLocation(source, "[instrument]")
    values, static = {}, {}
    for key, spec in table.items():
        if key in _INSTRUMENT_STATIC:
            if not (isinstance(spec, str) or (isinstance(spec, int) and not isinstance(spec, bool))):
                raise where.error(f"must be a layer's name or 0-based position, got {spec!r}", key)
            if isinstance(spec, str) and spec not in layer_names:
                raise where.error(f"no layer named {spec!r} (layers: {layer_names})", key)
            if isinstance(spec, int) and not 0 <= spec < len(layer_names):
                raise where.error(f"the stack has {len(layer_names)} layer(s), no layer {spec}", key)
            static[key] = spec
            continue
        if isinstance(spec, dict) and not any(k in spec for k in ("value",) + ANNOTATION_KEYS):
            raise where.error(f"a number or {{ value = ..., free = true, min = ..., max = ... }}, got {spec!r}", key)
        plain = annotated(where, key, spec, ("datasets", "all", key), "other", annotations, spectral=False)
        values[key] = read_number(where, key, plain)
    return InstrumentSettings(values, static, f"{source}: [instrument]")


def instrument_settings(d: Mapping, source: str) -> InstrumentSettings:
    """The ``[instrument]`` table of a parsed stack file ``d`` (from :func:`read_toml`; empty
    settings when it has none), checked like the rest of the file; ``source`` names the file in
    messages. Apply it to a geometry with :func:`instrument_geometry`."""
    table = d.get("instrument", {}) if isinstance(d, Mapping) else {}
    if not isinstance(table, Mapping):
        raise LayerstackError(f"{source}: instrument: must be a table [instrument], got {table!r}")
    names = [t.get("name") if isinstance(t, Mapping) else None for t in d.get("layers", [])]
    names = [n if isinstance(n, str) else f"layer {i + 1}" for i, n in enumerate(names)]
    return read_instrument_table(source, table, None, names)


def load_instrument(path) -> InstrumentSettings:
    """The ``[instrument]`` table of a stack file (:func:`instrument_settings` of the file read)."""
    path = Path(path)
    return instrument_settings(read_toml(path), str(path))


def instrument_geometry(geometry, settings: InstrumentSettings, *, partial: bool = False):
    """``geometry`` with the fields of ``settings`` set. Each key must be a field of it (a key
    that is not, e.g. ``bandwidth_nm`` for a sphere, is a :class:`LayerstackError` naming the
    key, the geometry and its fields) unless ``partial`` (several geometries share one table:
    each takes the keys it has; :func:`check_instrument_used` then checks that every key was
    taken by one). Returns the geometry unchanged when no key applies."""
    given = {**settings.values, **settings.static}
    fields = [f.name for f in dataclasses.fields(geometry)]
    if not partial:
        for key in given:
            if key not in fields:
                raise LayerstackError(f"{settings.where}: {key}: not a field of the geometry {geometry.label!r} "
                                      f"({type(geometry).__name__}; its fields: {', '.join(fields)})")
    given = {k: v for k, v in given.items() if k in fields}
    return dataclasses.replace(geometry, **given) if given else geometry


def check_instrument_used(settings: InstrumentSettings, geometries) -> None:
    """Raise naming the key when a key of ``settings`` is a field of none of ``geometries``."""
    fields = {f.name for g in geometries for f in dataclasses.fields(g)}
    for key in {**settings.values, **settings.static}:
        if key not in fields:
            labels = ", ".join(g.label for g in geometries) or "none"
            raise LayerstackError(f"{settings.where}: {key}: not a field of any geometry asked for ({labels})")
