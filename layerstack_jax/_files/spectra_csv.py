r"""Spectra as CSV files and wavelength grids: :func:`read_csv_columns` (numeric tables with a
header), :func:`read_spectra_csv` (``wavelength_nm`` then one column per spectrum),
:func:`save_spectra_csv` and :func:`parse_wavelengths` (``"380:780:5"``, ``"550"``,
``"450,550,650"``; nm).
"""

from __future__ import annotations

import csv
import math
import re
from pathlib import Path
from typing import Iterable, Mapping, Optional

import numpy as np

from .._base.validate import LayerstackError
from .readers.common import TextLines, is_missing, refuse_cut_number
from .readers.delimited import names_an_angle

__all__ = ["read_csv_columns", "read_spectra_csv", "is_spectra_csv", "save_spectra_csv", "parse_values", "parse_wavelengths"]


def delimiter_of(header: str) -> str:
    """The column separator of a CSV, from its header: ``,`` unless the header is separated by
    ``;`` or tabs (spreadsheets in locales that write decimal commas use ``;``)."""
    return next((d for d in (",", ";", "\t") if d in header), ",")


def _fields(line: str, delimiter: str = ",") -> list[str]:
    """The fields of one CSV line, quotes removed (R's ``write.csv`` and Excel quote headers:
    ``"wavelength_nm","sample 1"``), surrounding spaces stripped."""
    return [f.strip() for f in next(csv.reader([line], delimiter=delimiter, skipinitialspace=True))]


def _number(token: str, decimal_comma: bool) -> Optional[float]:
    try:
        return float(token)
    except ValueError:
        if decimal_comma and token.count(",") == 1 and "." not in token:
            try:
                return float(token.replace(",", "."))
            except ValueError:
                return None
        return None


def content_lines(path: Path) -> list[tuple[int, str]]:
    """``[(line number, stripped text)]`` of a text file, blank and ``#`` lines dropped; the list's
    ``complete`` attribute says whether the file ends with a line end (a cut file usually does not)."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise LayerstackError(f"{path}: file not found") from None
    except (OSError, UnicodeDecodeError) as e:
        raise LayerstackError(f"{path}: cannot read: {e}") from None
    lines = [(i + 1, line.strip()) for i, line in enumerate(text.splitlines())]
    out = TextLines((i, line) for i, line in lines if line and not line.startswith("#"))
    out.complete = not text.strip() or text.rstrip(" \t").endswith(("\n", "\r"))
    return out


def numeric_rows(path, lines, names, *, delimiter: str = ",", missing_in: Iterable[int] = ()) -> np.ndarray:
    """Data rows ``[(line_no, text), …]`` of a CSV as a ``(rows, len(names))`` float array; every
    problem raises :class:`LayerstackError` naming the file, line and column.

    ``delimiter``: the column separator (``;`` or a tab also allows decimal commas, ``0,5``).
    ``missing_in``: the indices of the columns where a missing value — an empty cell, ``NaN``,
    ``NA``, ``#N/A`` — is allowed and read as NaN (a point to mask); elsewhere it is an error, as
    is an infinite value. A file that does not end with a line end and whose last number is
    written shorter than in every earlier row (cut inside it) is refused."""
    missing_in = set(missing_in)
    decimal_comma = delimiter != ","
    rows, fields_of = [], []
    for line_no, line in lines:
        fields = _fields(line, delimiter)
        if len(fields) != len(names):
            hint = ""
            if len(fields) < len(names) and line_no == lines[-1][0]:
                hint = " (truncated file?)"
            if delimiter == "," and len(fields) > len(names) and re.search(r"\d,\d", line):
                hint = " (decimal commas? they need ';' or tabs between the columns)"
            raise LayerstackError(
                f"{path}: line {line_no}: {len(fields)} fields for {len(names)} columns ({', '.join(names)}){hint}")
        row = []
        for k, f in enumerate(fields):
            v = _number(f, decimal_comma)
            where = f"{path}: line {line_no}: column {names[k]!r} (column {k + 1})"
            if v is None and is_missing(f) and k in missing_in:
                v = math.nan
            elif v is None and is_missing(f):
                raise LayerstackError(f"{where}: no value ({f!r}); this column needs a number in every row")
            elif v is None:
                raise LayerstackError(f"{where}: {f!r} is not a number (in {line!r})")
            elif not math.isfinite(v) and not (math.isnan(v) and k in missing_in):
                raise LayerstackError(f"{where}: NaN or infinite value {f!r}")
            row.append(v)
        rows.append(row)
        fields_of.append((line_no, fields))
    if not rows:
        raise LayerstackError(f"{path}: no data rows after the header")
    refuse_cut_number(path, lines if isinstance(lines, TextLines) else TextLines(), fields_of[-1][0],
                      fields_of[-1][1], [f for _, f in fields_of[:-1]], names)
    return np.asarray(rows, dtype=float)


def read_csv_columns(path, required: Iterable[str], optional: Iterable[str] = ()) -> dict[str, np.ndarray]:
    """Read a numeric CSV file with a header row into ``{column: float array}``.

    Columns are matched case-insensitively and may come in any order; ``required`` ones must be
    present, ``optional`` ones may be, any other column is an error. Blank lines and lines
    starting with ``#`` are skipped; columns are separated by commas, or by ``;`` or tabs (then
    decimal commas are read). Raises :class:`LayerstackError` naming the file, line and column
    for a missing file, a missing header, a short or non-numeric row, or non-finite values
    (a table has no missing points). Does not check the wavelength order (callers do).
    """
    path = Path(path)
    required = [c.lower() for c in required]
    optional = [c.lower() for c in optional]
    expected = ", ".join(required + [f"[{c}]" for c in optional])
    lines = content_lines(path)
    if not lines:
        raise LayerstackError(f"{path}: empty file (expected a header row {expected} and data rows)")
    header_line, header = lines[0]
    delimiter = delimiter_of(header)
    names = [h.lower() for h in _fields(header, delimiter)]

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
    data = numeric_rows(path, _rest(lines), names, delimiter=delimiter)
    return {name: data[:, j] for j, name in enumerate(names)}


def _rest(lines):
    """``lines`` without the header, keeping whether the file ended with a line end."""
    out = TextLines(lines[1:])
    out.complete = getattr(lines, "complete", True)
    return out


def is_spectra_csv(path) -> bool:
    """True when the file's header is a spectra CSV's (:func:`read_spectra_csv`): ``wavelength_nm``
    first (after R's unnamed row-name column), in any of the separators read, and no angle column
    (``angle``, ``aoi`` …: points at angles make a measurement CSV,
    :func:`~layerstack_jax.io.read_measurement_csv`). A file that cannot be read answers False."""
    try:
        lines = content_lines(Path(path))
    except LayerstackError:
        return False
    if not lines:
        return False
    names = [n.lower() for n in _fields(lines[0][1], delimiter_of(lines[0][1]))]
    first = names[1] if len(names) > 1 and names[0] == "" else names[0] if names else ""
    return first == "wavelength_nm" and not names_an_angle(names)


def read_spectra_csv(path) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Read measured spectra: a header row ``wavelength_nm, name1, name2, …`` then numbers.

    Returns ``(wavelength_nm, {name: values})``: wavelengths in nm, increasing, and each spectrum
    as it is in the file (no unit conversion), all 1-D arrays of shape ``(wl,)``.

    * Lines starting with ``#`` (e.g. a note that the data are synthetic) and blank lines are
      skipped.
    * Columns are separated by commas, or by ``;`` or tabs — then decimal commas (``0,5``) are
      read, as spreadsheets in such locales write them.
    * A missing value — an empty cell, ``NaN``, ``NA``, ``#N/A`` — is NaN in its spectrum: a
      point to mask (``np.isfinite``; ``layerstack fit`` masks it), never a number. Every row needs
      its wavelength.
    * Wavelengths listed in decreasing order are put in increasing order (rows reversed).

    Raises :class:`LayerstackError` naming the file, line and column for a missing
    ``wavelength_nm`` column, no spectrum column, a duplicate name, a short or non-numeric row,
    an infinite value, wavelengths ≤ 0, repeated or out of order, or a file cut inside its last
    number.
    """
    path = Path(path)
    lines = content_lines(path)
    if not lines:
        raise LayerstackError(f"{path}: empty file (expected a header wavelength_nm,<spectrum names…> and data rows)")
    header_line, header = lines[0]
    delimiter = delimiter_of(header)
    names = _fields(header, delimiter)
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
    wl_index = 1 if drop_row_names else 0
    data = numeric_rows(path, _rest(lines), names, delimiter=delimiter,
                        missing_in=[k for k in range(len(names)) if k > wl_index])
    if drop_row_names:
        data, names = data[:, 1:], names[1:]
    wl = data[:, 0]
    line_nos = [i for i, _ in lines[1:]]
    if np.any(wl <= 0):
        r = int(np.argmax(wl <= 0))
        raise LayerstackError(f"{path}: line {line_nos[r]}: column 'wavelength_nm': {wl[r]:g} is not > 0")
    step = np.diff(wl)
    if wl.size > 1 and np.all(step < 0):  # listed from red to blue: put in increasing order
        data, line_nos = data[::-1], line_nos[::-1]
        wl, step = data[:, 0], -step[::-1]
    if np.any(step <= 0):
        r = int(np.argmax(step <= 0)) + 1
        why = "repeats the wavelength before it" if step[r - 1] == 0 else f"comes after {wl[r - 1]:g}"
        raise LayerstackError(
            f"{path}: line {line_nos[r]}: column 'wavelength_nm': {wl[r]:g} {why}: wavelengths must increase "
            "(or decrease) strictly"
        )
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

