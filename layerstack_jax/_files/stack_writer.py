"""Stack files written: a :class:`~layerstack_jax.Stack` as a dict in the stack-file schema
(:func:`stack_to_dict`, the inverse of :func:`~layerstack_jax.io.stack_from_dict`) and as TOML
(:func:`save_stack`, with a small TOML writer: the standard library reads TOML but does not
write it).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Mapping

import numpy as np

from .._base.leaves import file_fields
from .._base.validate import LayerstackError, is_concrete
from .._media.materials import Cauchy, Index, Material, Sellmeier, Tabulated
from .._stacks.stack import Stack, TabulatedSpectrum
from .material_file import MIXTURES, MODELS

__all__ = ["stack_to_dict", "save_stack"]


def _scalar(x, what: str) -> float:
    if not is_concrete(x) or np.ndim(x) != 0:
        raise LayerstackError(f"stack_to_dict: {what} must be a concrete scalar, got {x!r}")
    return float(np.asarray(x))


def _material_to_dict(m: Material, what: str, out: dict) -> None:
    if isinstance(m, Index):
        if np.ndim(m.n) or np.ndim(m.k):
            raise LayerstackError(f"stack_to_dict: {what} is sampled on a wavelength grid; use a Tabulated material")
        out["n"] = _scalar(m.n, f"{what} n")
        k = _scalar(m.k, f"{what} k")
    elif isinstance(m, Cauchy):
        out["n"] = {"cauchy": [_scalar(m.A, f"{what} A"), _scalar(m.B, f"{what} B"), _scalar(m.C, f"{what} C")]}
        k = _scalar(m.k, f"{what} k")
    elif isinstance(m, Sellmeier):
        out["n"] = {"sellmeier": {"B": np.atleast_1d(np.asarray(m.B, float)).tolist(),
                                  "C": np.atleast_1d(np.asarray(m.C, float)).tolist()}}
        k = _scalar(m.k, f"{what} k")
    elif type(m) in _MODEL_NAMES:  # a dispersion model or an effective medium: its fields by name
        out["n"] = {_MODEL_NAMES[type(m)]: _fields_to_dict(m, what)}
        k = 0.0
    elif isinstance(m, Tabulated):
        table = {"wavelength_nm": list(m.wavelength_nm), "n": np.asarray(m.n, float).tolist()}
        if m.k is not None:
            table["k"] = np.asarray(m.k, float).tolist()
        out["n"] = table
        k = 0.0
    else:
        raise LayerstackError(f"stack_to_dict: cannot write {what} of type {type(m).__name__}")
    if k != 0.0:
        out["k"] = k


_MODEL_NAMES = {cls: name for name, cls in {**MODELS, **MIXTURES}.items()}


def _number_or_list(x, what: str):
    if is_concrete(x) and np.ndim(x) == 1:
        return np.asarray(x, float).tolist()
    return _scalar(x, what)


def _fields_to_dict(m: Material, what: str) -> dict:
    """The coefficients of a model (:data:`MODELS`) or the materials and fractions of an effective
    medium (:data:`MIXTURES`) as the stack file writes them."""
    if type(m) in MIXTURES.values():
        materials = []
        for i, c in enumerate(m.materials):
            sub: dict = {}
            _material_to_dict(c, f"{what} material {i + 1}", sub)
            materials.append(sub if "k" in sub else sub["n"])
        return {"materials": materials, "fractions": _number_or_list(m.fractions, f"{what} fractions")}
    return {f.name: _number_or_list(getattr(m, f.name), f"{what} {f.name}") for f in dataclasses.fields(m) if f.init}


def _spectrum_to_dict(x, what: str):
    if isinstance(x, TabulatedSpectrum):
        return {"wavelength_nm": list(x.wavelength_nm), "values": np.asarray(x.values, float).tolist()}
    if callable(x) or np.ndim(x):
        raise LayerstackError(f"stack_to_dict: {what} must be a scalar or a TabulatedSpectrum")
    return _scalar(x, what)


def stack_to_dict(stack: Stack) -> dict:
    """The inverse of :func:`stack_from_dict`: a dict in the stack-file schema, tables inline.

    Works for stacks made of scalars, :class:`Index` (scalar), :class:`Cauchy`,
    :class:`Sellmeier`, :class:`Tabulated`, :class:`TabulatedSpectrum`, the dispersion models
    (:class:`TaucLorentz` …) and the effective media (:class:`Bruggeman`, :class:`Looyenga`) of
    these, over any exit (a :class:`KubelkaMunk` body's paint writes its own entries: K, S or one
    ``[[kubelka_munk.pigments]]`` table per pigment of a mixture); raises
    :class:`LayerstackError` for arrays sampled on a grid or traced values.
    """
    d: dict = {"ambient": {}}
    _material_to_dict(stack.ambient, "ambient", d["ambient"])
    layers = []
    for i, layer in enumerate(stack.layers):
        t: dict = {"name": layer.name or f"layer {i + 1}"}
        _material_to_dict(layer.index, f"layer {i + 1}", t)
        t["thickness_nm"] = _scalar(layer.thickness, f"layer {i + 1} thickness")
        t["coherent"] = bool(layer.coherent)
        if layer.alpha is not None:
            t["alpha_per_nm"] = _spectrum_to_dict(layer.alpha, f"layer {i + 1} alpha")
        layers.append(t)
    d["layers"] = layers
    table = stack.exit.table  # the exit's own table; its numbers under the keys its fields declare
    d[table] = {}
    _material_to_dict(stack.exit.index, table, d[table])
    keys = {field: key for key, field in file_fields(stack.exit).items()}
    for f in dataclasses.fields(stack.exit):
        value = getattr(stack.exit, f.name)
        if f.name == "index" or f.metadata.get("static") or value is None:
            continue
        if f.name in keys:
            d[table][keys[f.name]] = _spectrum_to_dict(value, f"{table} {keys[f.name]}")
        elif callable(getattr(value, "file_table", None)):  # a part that writes its own entries (a paint)
            d[table].update(_entries_to_dict(value.file_table(), table))
        else:
            raise LayerstackError(f"stack_to_dict: the [{table}] field {f.name!r} has no stack-file form here; "
                                  "write this stack's file by hand")
    return d


def _entries_to_dict(entries: dict, where: str) -> dict:
    """A part's own stack-file entries (``file_table()``) with their values in file form: numbers
    and spectra as :func:`_spectrum_to_dict` writes them, lists of tables entry by entry."""
    out = {}
    for key, value in entries.items():
        if isinstance(value, str):
            out[key] = value
        elif isinstance(value, list):
            out[key] = [_entries_to_dict(v, f"{where}.{key}") for v in value]
        else:
            out[key] = _spectrum_to_dict(value, f"{where} {key}")
    return out


# --------------------------------------------------------------------------- TOML writer
_BARE_KEY = frozenset("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789_-")


def _toml_key(key) -> str:
    key = str(key)
    return key if key and set(key) <= _BARE_KEY else _toml_string(key)


def _toml_string(text: str) -> str:
    escapes = {'"': '\\"', "\\": "\\\\", "\n": "\\n", "\t": "\\t", "\r": "\\r", "\b": "\\b", "\f": "\\f"}
    out = []
    for c in text:
        if c in escapes:
            out.append(escapes[c])
        elif ord(c) < 0x20 or ord(c) == 0x7F:
            out.append(f"\\u{ord(c):04X}")
        else:
            out.append(c)
    return '"' + "".join(out) + '"'


def _toml_value(x, what: str) -> str:
    """One TOML value (inline: strings, booleans, finite numbers, arrays, inline tables)."""
    if isinstance(x, (bool, np.bool_)):
        return "true" if x else "false"
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    if isinstance(x, (float, np.floating)):
        v = float(x)
        if not math.isfinite(v):
            raise LayerstackError(f"save_stack: {what} is not finite ({v!r})")
        return repr(v)  # shortest round-trip representation
    if isinstance(x, str):
        return _toml_string(x)
    if isinstance(x, np.ndarray):
        x = x.tolist()
    if isinstance(x, (list, tuple)):
        return "[" + ", ".join(_toml_value(v, what) for v in x) + "]"
    if isinstance(x, Mapping):
        if not x:
            return "{}"
        return "{ " + ", ".join(f"{_toml_key(k)} = {_toml_value(v, f'{what}.{k}')}" for k, v in x.items()) + " }"
    raise LayerstackError(f"save_stack: cannot write {what} of type {type(x).__name__}")


def _is_array_of_tables(x) -> bool:
    return isinstance(x, list) and bool(x) and all(isinstance(v, Mapping) for v in x)


def _toml_table(d: Mapping, what: str) -> list[str]:
    """The lines of table ``what``: its entries (inline values), then its arrays of tables
    (``[[what.key]]``, e.g. a Kubelka–Munk body's pigments)."""
    lines = [f"{_toml_key(k)} = {_toml_value(v, f'{what}.{k}')}" for k, v in d.items() if not _is_array_of_tables(v)]
    for k, v in d.items():
        if _is_array_of_tables(v):
            for item in v:
                lines += ["", f"[[{what}.{_toml_key(k)}]]", *_toml_table(item, f"{what}.{_toml_key(k)}")]
    return lines


def _dumps_stack(d: Mapping, header: str = "") -> str:
    """A stack dict (schema in the module docstring, e.g. from :func:`stack_to_dict`) as TOML
    text, ``header`` written first as ``#`` comment lines: top-level values, then every table
    (``[ambient]``, ``[[layers]]``, the exit's table …) in the dict's order."""
    lines = [f"# {line}".rstrip() for line in header.splitlines()]
    if lines:
        lines.append("")
    for key, value in d.items():
        if not isinstance(value, Mapping) and not _is_array_of_tables(value):
            lines.append(f"{_toml_key(key)} = {_toml_value(value, key)}")
    for key, value in d.items():
        if _is_array_of_tables(value):
            for item in value:
                lines += ["", f"[[{_toml_key(key)}]]", *_toml_table(item, _toml_key(key))]
        elif isinstance(value, Mapping):
            lines += ["", f"[{_toml_key(key)}]", *_toml_table(value, _toml_key(key))]
    return "\n".join(lines) + "\n"


def save_stack(path, stack, *, header: str = "") -> Path:
    """Write a stack file (TOML) readable by :func:`load_stack`.

    Args:
        path: output file; missing parent directories are created.
        stack: a :class:`Stack` (converted by :func:`stack_to_dict`: materials inline) or a dict
            in the stack-file schema (kept as given, e.g. ``{ material = "Au" }`` references;
            relative table file names must then be valid from the output's directory).
        header: free text written first as ``#`` comment lines.
    Returns the path written.

    Units as in the stack-file schema (``thickness_nm`` in nm, ``alpha_per_nm`` in 1/nm). A
    :class:`Stack`'s leaves must be scalars or tables with their own wavelengths
    (:class:`Tabulated`, :class:`TabulatedSpectrum`, shape ``(table,)``): arrays sampled on a
    model grid or traced values raise :class:`LayerstackError` (see :func:`stack_to_dict`).
    """
    d = stack_to_dict(stack) if isinstance(stack, Stack) else stack
    if not isinstance(d, Mapping):
        raise LayerstackError(f"save_stack: expected a Stack or a dict, got {type(stack).__name__}")
    text = _dumps_stack(d, header)
    path = Path(path)
    if path.parent and not path.parent.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    return path
