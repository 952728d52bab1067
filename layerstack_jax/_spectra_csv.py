r"""Spectra as CSV files and wavelength grids: :func:`read_csv_columns` (numeric tables with a
header), :func:`read_spectra_csv` (``wavelength_nm`` then one column per spectrum),
:func:`save_spectra_csv` and :func:`parse_wavelengths` (``"380:780:5"``, ``"550"``,
``"450,550,650"``; nm).
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Iterable, Mapping

import numpy as np

from ._validate import LayerstackError

__all__ = ["read_csv_columns", "read_spectra_csv", "save_spectra_csv", "parse_values", "parse_wavelengths"]


def _fields(line: str) -> list[str]:
    """The comma-separated fields of one CSV line, quotes removed (R's ``write.csv`` and Excel
    quote headers: ``"wavelength_nm","sample 1"``), surrounding spaces stripped."""
    return [f.strip() for f in next(csv.reader([line], skipinitialspace=True))]


def content_lines(path: Path) -> list[tuple[int, str]]:
    """``[(line number, stripped text)]`` of a text file, blank and ``#`` lines dropped."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise LayerstackError(f"{path}: file not found") from None
    except (OSError, UnicodeDecodeError) as e:
        raise LayerstackError(f"{path}: cannot read: {e}") from None
    lines = [(i + 1, line.strip()) for i, line in enumerate(text.splitlines())]
    return [(i, line) for i, line in lines if line and not line.startswith("#")]


def numeric_rows(path, lines, names) -> np.ndarray:
    """Data rows ``[(line_no, text), …]`` of a CSV as a ``(rows, len(names))`` float array; every
    problem raises :class:`LayerstackError` naming the file and line."""
    rows = []
    for line_no, line in lines:
        fields = _fields(line)
        if len(fields) != len(names):
            raise LayerstackError(f"{path}: line {line_no}: {len(fields)} fields for {len(names)} columns ({', '.join(names)})")
        try:
            row = [float(f) for f in fields]
        except ValueError:
            raise LayerstackError(f"{path}: line {line_no}: not a number in {line!r}") from None
        if not all(math.isfinite(v) for v in row):
            raise LayerstackError(f"{path}: line {line_no}: NaN or infinite value in {line!r}")
        rows.append(row)
    if not rows:
        raise LayerstackError(f"{path}: no data rows after the header")
    return np.asarray(rows, dtype=float)


def read_csv_columns(path, required: Iterable[str], optional: Iterable[str] = ()) -> dict[str, np.ndarray]:
    """Read a numeric CSV file with a header row into ``{column: float array}``.

    Columns are matched case-insensitively and may come in any order; ``required`` ones must be
    present, ``optional`` ones may be, any other column is an error. Blank lines and lines
    starting with ``#`` are skipped. Raises :class:`LayerstackError` naming the file (and line)
    for a missing file, a missing header, a short or non-numeric row, or non-finite values.
    Does not check the wavelength order (callers do).
    """
    path = Path(path)
    required = [c.lower() for c in required]
    optional = [c.lower() for c in optional]
    expected = ", ".join(required + [f"[{c}]" for c in optional])
    lines = content_lines(path)
    if not lines:
        raise LayerstackError(f"{path}: empty file (expected a header row {expected} and data rows)")
    header_line, header = lines[0]
    names = [h.lower() for h in _fields(header)]

    def _is_float(s):
        try:
            float(s)
            return True
        except ValueError:
            return False

    if all(_is_float(h) for h in names):
        raise LayerstackError(f"{path}: line {header_line}: header row required (columns {expected}), got numbers")
    for name in names:
        if name not in required and name not in optional:
            raise LayerstackError(f"{path}: line {header_line}: unknown column {name!r}; expected columns {expected}")
        if names.count(name) > 1:
            raise LayerstackError(f"{path}: line {header_line}: column {name!r} appears twice")
    for name in required:
        if name not in names:
            raise LayerstackError(f"{path}: line {header_line}: missing column {name!r}; expected columns {expected}")
    data = numeric_rows(path, lines[1:], names)
    return {name: data[:, j] for j, name in enumerate(names)}


def read_spectra_csv(path) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Read measured spectra: a header row ``wavelength_nm, name1, name2, …`` then numbers.

    Returns ``(wavelength_nm, {name: values})``: wavelengths in nm and each spectrum as it is in
    the file (no unit conversion), all 1-D arrays of shape ``(wl,)``. Lines starting with ``#`` (e.g. a note that the
    data are synthetic) and blank lines are skipped. Raises :class:`LayerstackError` naming the
    file and line for a missing ``wavelength_nm`` column, no spectrum column, a duplicate name,
    a short or non-numeric row, NaN, or wavelengths that do not increase strictly.
    """
    path = Path(path)
    lines = content_lines(path)
    if not lines:
        raise LayerstackError(f"{path}: empty file (expected a header wavelength_nm,<spectrum names…> and data rows)")
    header_line, header = lines[0]
    names = _fields(header)
    drop_row_names = len(names) > 1 and names[0] == "" and names[1].lower() == "wavelength_nm"
    if drop_row_names:  # R's write.csv writes row names first, under an empty header
        names = ["row_name"] + names[1:]
    elif not names or names[0].lower() != "wavelength_nm":
        raise LayerstackError(f"{path}: line {header_line}: the first column must be wavelength_nm, got {names[0]!r}")
    if len(names) < 2:
        raise LayerstackError(f"{path}: line {header_line}: no spectrum column after wavelength_nm")
    for n in names[1:]:
        if not n:
            raise LayerstackError(f"{path}: line {header_line}: empty column name")
        if names.count(n) > 1:
            raise LayerstackError(f"{path}: line {header_line}: column {n!r} appears twice")
    data = numeric_rows(path, lines[1:], names)
    if drop_row_names:
        data, names = data[:, 1:], names[1:]
    wl = data[:, 0]
    if np.any(wl <= 0) or np.any(np.diff(wl) <= 0):
        raise LayerstackError(f"{path}: wavelength_nm must be > 0 and increase strictly")
    return wl, {n: data[:, j + 1] for j, n in enumerate(names[1:])}



def save_spectra_csv(path, wavelength_nm, columns: Mapping[str, object], *, fmt: str = "%.10g") -> Path:
    """Write ``wavelength_nm`` and the named spectra as a CSV file with a header row.

    Args:
        path: output file; missing parent directories are created.
        wavelength_nm: ``(wl,)`` wavelengths in nm (first column).
        columns: ``{name: (wl,) values}`` in column order.
    Returns the path written.
    """
    path = Path(path)
    wl = np.asarray(wavelength_nm, dtype=float)
    if wl.ndim != 1:
        raise LayerstackError(f"save_spectra_csv: wavelength_nm must be 1-D, got shape {wl.shape}")
    names = ["wavelength_nm"]
    data = [wl]
    for name, values in columns.items():
        name = str(name)
        if not name or any(c in name for c in ',"\n\r'):
            raise LayerstackError(f"save_spectra_csv: bad column name {name!r} (no commas, quotes or newlines)")
        if name in names:
            raise LayerstackError(f"save_spectra_csv: column {name!r} given twice")
        v = np.asarray(values, dtype=float)
        if v.shape != wl.shape:
            raise LayerstackError(f"save_spectra_csv: column {name!r} has shape {v.shape}, expected {wl.shape}")
        names.append(name)
        data.append(v)
    if path.parent and not path.parent.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
    np.savetxt(path, np.column_stack(data), delimiter=",", header=",".join(names), comments="", fmt=fmt)
    return path


def parse_values(text, what: str = "values", example: str = "380:780:5") -> np.ndarray:
    """Numbers from ``"start:stop:step"`` (stop included when it falls on the grid; step > 0,
    stop >= start), a single value ``"550"`` or a comma list ``"450,550,650"``: a 1-D float
    array, all finite. ``what`` names the quantity in the error (e.g. ``"wavelengths"``,
    ``"--vary varnish.thickness_nm"``), ``example`` shows a valid range."""
    t = str(text).strip()
    bad = LayerstackError(
        f"bad {what} {text!r}: use start:stop:step (e.g. {example}), one value or a comma list of numbers"
    )
    try:
        if ":" in t:
            parts = t.split(":")
            if len(parts) != 3:
                raise bad
            start, stop, step = (float(p) for p in parts)
            if not all(map(math.isfinite, (start, stop, step))):
                raise bad
            if step <= 0:
                raise LayerstackError(f"bad {what} {text!r}: step must be > 0")
            if stop < start:
                raise LayerstackError(f"bad {what} {text!r}: stop must be >= start")
            count = int(math.floor((stop - start) / step + 1e-9)) + 1
            values = start + step * np.arange(count)
        else:
            values = np.asarray([float(p) for p in t.split(",")], dtype=float)
    except LayerstackError:  # a ValueError too: the specific message stands
        raise
    except ValueError:
        raise bad from None
    if values.size == 0 or not np.all(np.isfinite(values)):
        raise bad
    return values


def parse_wavelengths(text) -> np.ndarray:
    """Wavelength grid in nm from ``"start:stop:step"`` (stop included when it falls on the
    grid), a single value ``"550"`` or a comma list ``"450,550,650"`` (strictly increasing).
    Returns a 1-D float array of shape ``(wl,)`` in nm.
    """
    wl = parse_values(text, "wavelengths", "380:780:5 in nm")
    if np.any(wl <= 0):
        raise LayerstackError(f"bad wavelengths {text!r}: wavelengths must be > 0 nm")
    if np.any(np.diff(wl) <= 0):
        raise LayerstackError(f"bad wavelengths {text!r}: wavelengths must increase strictly")
    return wl

