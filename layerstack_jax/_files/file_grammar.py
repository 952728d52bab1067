r"""The grammar shared by every TOML input file (stack files, fit and design files): where a
value is (:class:`FileLocation`, for messages naming file, table and key), unknown-key
rejection with a "did you mean" hint, numbers and number lists with their ranges, wavelength
grids, and reading the TOML itself. Each check raises :class:`~layerstack_jax.LayerstackError`
naming file, table and key.

Public through :mod:`layerstack_jax.io` for the file formats built on the stack file (the design
files of :mod:`fitting`): one grammar, one set of messages.
"""

from __future__ import annotations

import difflib
import math
import tomllib
from pathlib import Path
from typing import Iterable, Mapping, Optional

import numpy as np

from .._base.validate import LayerstackError

__all__ = ["FileLocation", "named_tables", "reject_unknown_keys", "is_number", "read_number", "read_number_list", "check_grid",
           "check_range", "read_toml"]


class FileLocation:
    """Where we are in a file, for error messages: ``<file>: <table>: key '<key>': <what>``."""

    def __init__(self, source: str, table: str):
        self.source = source
        self.table = table

    def error(self, what: str, key: Optional[str] = None) -> LayerstackError:
        place = f"{self.table}: key {key!r}" if key else self.table
        return LayerstackError(f"{self.source}: {place}: {what}")


def reject_unknown_keys(where: FileLocation, table: Mapping, allowed: Iterable[str]) -> None:
    allowed = tuple(allowed)
    for key in table:
        if key not in allowed:
            close = difflib.get_close_matches(str(key), allowed, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise where.error(f"unknown key {key!r}{hint}; allowed keys: {', '.join(allowed)}")


def is_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def read_number(where: FileLocation, key: str, x, *, minimum: Optional[float] = None, maximum: Optional[float] = None,
            positive: bool = False, what: str = "") -> float:
    label = f" ({what})" if what else ""
    if not is_number(x):
        raise where.error(f"must be a number{label}, got {x!r}", key)
    v = float(x)
    if not math.isfinite(v):
        raise where.error(f"must be finite{label}, got {v!r}", key)
    if positive and v <= 0:
        raise where.error(f"must be > 0{label}, got {v!r}", key)
    if minimum is not None and v < minimum:
        raise where.error(f"must be >= {minimum:g}{label}, got {v!r}", key)
    if maximum is not None and v > maximum:
        raise where.error(f"must be <= {maximum:g}{label}, got {v!r}", key)
    return v


def read_number_list(where: FileLocation, key: str, x, what: str) -> np.ndarray:
    if not isinstance(x, list) or not x or not all(is_number(v) for v in x):
        raise where.error(f"{what} must be a non-empty list of numbers, got {x!r}", key)
    a = np.asarray(x, dtype=float)
    if not np.all(np.isfinite(a)):
        raise where.error(f"{what} must be finite numbers, got {x!r}", key)
    return a


def check_grid(where: FileLocation, key: str, wl: np.ndarray, what: str) -> None:
    if wl.size < 2:
        raise where.error(f"{what}: needs at least 2 wavelengths, got {wl.size}", key)
    if np.any(wl <= 0):
        raise where.error(f"{what}: wavelengths must be > 0 nm", key)
    if np.any(np.diff(wl) <= 0):
        i = int(np.argmax(np.diff(wl) <= 0))
        raise where.error(
            f"{what}: wavelengths must increase strictly (wavelength_nm {wl[i]:g} is followed by {wl[i + 1]:g})", key
        )


def check_range(where: FileLocation, key: str, values: np.ndarray, what: str, lo=None, hi=None) -> None:
    if lo is not None and np.any(values < lo):
        raise where.error(f"{what}: values must be >= {lo:g}, got min {values.min():g}", key)
    if hi is not None and np.any(values > hi):
        raise where.error(f"{what}: values must be <= {hi:g}, got max {values.max():g}", key)



def read_toml(path: Path, what: str = "stack file") -> dict:
    """The parsed TOML file ``path``; a missing, unreadable or malformed file raises
    :class:`LayerstackError` naming the file (``what``: how the message calls it)."""
    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except FileNotFoundError:
        raise LayerstackError(f"{path}: {what} not found") from None
    except tomllib.TOMLDecodeError as e:
        raise LayerstackError(f"{path}: invalid TOML: {e}") from None
    except (OSError, UnicodeDecodeError) as e:
        raise LayerstackError(f"{path}: cannot read {what}: {e}") from None


def named_tables(source: str, raw, key: str, what: str) -> list[tuple[Mapping, str, FileLocation]]:
    """The entries of an array of tables ``[[key]]`` (``raw``, from the parsed file) as
    ``(table, name, where)``: ``name`` from the table's ``name`` key (default ``"<what> N"``),
    ``where`` the :class:`FileLocation` that names it in messages. A non-list, a non-table entry
    or an empty / non-string name raises :class:`LayerstackError`."""
    if not isinstance(raw, list) or not all(isinstance(t, Mapping) for t in raw):
        raise FileLocation(source, "top level").error(f"must be an array of tables, written [[{key}]]", key)
    out = []
    for i, t in enumerate(raw):
        name = t.get("name", f"{what} {i + 1}")
        label = f"[[{key}]] no. {i + 1}"
        if not isinstance(name, str) or not name:
            raise FileLocation(source, label).error(f"must be a non-empty string, got {name!r}", "name")
        out.append((t, name, FileLocation(source, f"{label} ({name!r})")))
    return out
