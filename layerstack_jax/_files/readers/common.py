"""What every reader shares: wavelength units, the error form (file, line, why), text and
number parsing, range checks, and the :class:`Format` record by which a reader registers itself
(its name, its reader and its sniffing test)."""

from __future__ import annotations

import math
import re
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional, Sequence

import numpy as np

from ..._base.validate import LayerstackError
from ..measurement import Measurement

#: h·c/e in eV·nm, from the exact SI constants (h = 6.62607015e-34 J s, c = 299792458 m/s,
#: e = 1.602176634e-19 C): λ[nm] = HC_EV_NM / E[eV].
HC_EV_NM = 6.62607015e-34 * 299792458.0 / 1.602176634e-19 * 1e9


# ---------------------------------------------------------------------------------------------
# units and small helpers
# ---------------------------------------------------------------------------------------------
_UNIT_ALIASES = {
    "nm": "nm",
    "nanometer": "nm",
    "nanometers": "nm",
    "nanometre": "nm",
    "nanometres": "nm",
    "a": "angstrom",
    "å": "angstrom",
    "angstrom": "angstrom",
    "angstroms": "angstrom",
    "um": "um",
    "µm": "um",
    "μm": "um",
    "micron": "um",
    "microns": "um",
    "micrometer": "um",
    "micrometers": "um",
    "micrometre": "um",
    "micrometres": "um",
    "ev": "eV",
    "1/cm": "1/cm",
    "cm-1": "1/cm",
    "cm^-1": "1/cm",
    "cm⁻¹": "1/cm",
    "wavenumber": "1/cm",
    "wavenumbers": "1/cm",
}


def unit_of(text: str) -> Optional[str]:
    """Canonical wavelength unit (``nm``, ``angstrom``, ``um``, ``eV``, ``1/cm``) of a unit word, or None."""
    return _UNIT_ALIASES.get(text.strip().strip(".").lower())


def wavelength_to_nm(x, unit: str) -> np.ndarray:
    """Convert wavelengths (or photon energies, wavenumbers) to vacuum wavelengths in nm.

    Args:
        x: values, any shape.
        unit: ``"nm"``, ``"angstrom"`` (Å), ``"um"`` (µm), ``"eV"`` (photon energy:
            λ = hc/E) or ``"1/cm"`` (wavenumber: λ = 10⁷/ν̃); aliases accepted (``"Angstroms"``, ``"µm"`` …).

    Returns:
        Wavelengths in nm, same shape.
    """
    canon = unit_of(unit) or unit
    x = np.asarray(x, dtype=float)
    if canon == "nm":
        return x
    if canon == "angstrom":
        return x / 10.0
    if canon == "um":
        return x * 1000.0
    if canon == "eV":
        return HC_EV_NM / x
    if canon == "1/cm":
        return 1e7 / x
    raise LayerstackError(f"unknown wavelength unit {unit!r} (nm, Angstroms, um, eV or 1/cm)")


def error(path, line: Optional[int], why: str) -> LayerstackError:
    where = f"{path}, line {line}" if line is not None else f"{path}"
    return LayerstackError(f"{where}: {why}")


class TextLines(list):
    """The lines of a text file without their line ends (a ``list[str]``), and whether the file
    ends with a line end (``complete``): a file cut while it was written usually does not."""

    complete: bool = True


def read_text(path) -> TextLines:
    """Lines of a text file (UTF-8, else Latin-1 as instruments on Windows write), without line ends."""
    path = Path(path)
    if not path.is_file():
        raise LayerstackError(f"{path}: no such file")
    raw = path.read_bytes()
    if b"\x00" in raw[:4096]:
        raise error(path, None, "binary file, not a text export (for NeXus/HDF5 use read_nexus)")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")
    text = text.replace("\x1a", "")
    lines = TextLines(text.splitlines())
    lines.complete = not text.strip() or text.rstrip(" \t").endswith(("\n", "\r"))
    return lines


def to_float(token: str) -> Optional[float]:
    """The number a token spells (``1.5``, ``-3e-2``, ``inf``, ``nan``), or None."""
    try:
        return float(token)
    except ValueError:
        return None


def numbers(tokens: Sequence[str]) -> Optional[list[float]]:
    out = [to_float(t) for t in tokens]
    return None if any(v is None for v in out) else out


def check_range(path, line, name: str, value: float, lo: float, hi: float, unit: str = "degrees") -> None:
    if not (math.isfinite(value) and lo <= value <= hi):
        raise error(path, line, f"{name} = {value!r} is not a number in [{lo:g}, {hi:g}] {unit}")


def warn_implausible(path, m: Measurement) -> Measurement:
    """Warn (not fail) when a measurement's values are possible in a file but not in nature:
    R or T beyond [-0.02, 1.02], or normalised Mueller elements beyond ±1.05."""
    v = np.asarray(m.values)
    if m.quantity in ("reflectance", "transmittance"):
        lo, hi = np.nanmin(v), np.nanmax(v)
        if lo < -0.02 or hi > 1.02:
            warnings.warn(
                f"{path}: {m.quantity} spans [{lo:.4g}, {hi:.4g}] (fraction): outside [0, 1]; check the unit "
                "(percent?) and the reference of the measurement",
                stacklevel=3,
            )
    elif m.quantity == "mueller" and m.mueller_normalized and np.nanmax(np.abs(v)) > 1.05:
        warnings.warn(f"{path}: normalised Mueller elements reach {np.nanmax(np.abs(v)):.4g} (beyond ±1)", stacklevel=3)
    return m


def check_angle(path, line, value: float) -> None:
    check_range(path, line, "angle of incidence", value, 0.0, 90.0)
    if value >= 90.0:
        raise error(path, line, f"angle of incidence = {value!r} must be below 90 degrees")



# ---------------------------------------------------------------------------------------------
# missing values and truncated files
# ---------------------------------------------------------------------------------------------
#: Cells that say "no value here" (spreadsheets, R, pandas): read as NaN, masked per point.
MISSING = frozenset({"", "nan", "na", "n/a", "#n/a", "null", "none", "-", "--"})


def is_missing(token: str) -> bool:
    """True for an empty cell or a spreadsheet's "no value" (``NaN``, ``NA``, ``#N/A`` …)."""
    return token.strip().strip('"').strip().lower() in MISSING


_DIGITS = re.compile(r"^[+-]?(\d*)(?:[.,](\d*))?(?:[eE]([+-]?\d*))?$")


def _written_precision(token: str) -> Optional[tuple[int, int, int]]:
    """(decimals, significant digits, exponent digits) of a number as written, or None."""
    m = _DIGITS.match(token.strip())
    if m is None or not (m.group(1) or m.group(2)):
        return None
    whole, frac, exp = m.group(1) or "", m.group(2) or "", m.group(3)
    significant = (whole + frac).lstrip("0")
    return len(frac), len(significant), -1 if exp is None else len(exp.lstrip("+-"))


def refuse_cut_number(path, lines: TextLines, line: int, tokens: Sequence[str], earlier: Sequence[Sequence[str]],
                      names: Optional[Sequence[str]] = None) -> None:
    """Refuse a file that ends inside a number.

    ``tokens`` are the fields of the last data row (line ``line``), ``earlier`` the fields of the
    rows of the same kind before it. When the file does not end with a line end and the row's last
    field is written with fewer decimals, significant or exponent digits than that field in the
    earlier rows — in all of them, sharing one precision (a fixed format), or in 95 % of ten or
    more (up to the last 50: an export that drops trailing zeros) — the writing was cut inside
    that number: its value is wrong, so the file is refused naming the line and the column. A
    short file typed by hand, its numbers written with varying precision, is not refused.
    """
    if lines.complete or not tokens or not earlier:
        return
    fewest = min(len(r) for r in earlier)
    if len(tokens) < fewest:
        raise error(path, line, f"the file ends inside this row: {len(tokens)} fields where every earlier row has "
                                f"{fewest} or more (truncated file?)")
    k = len(tokens) - 1
    if not tokens[k].strip():  # an empty last cell: a missing point, masked, never misread
        return
    last = _written_precision(tokens[k])
    others = [_written_precision(r[k]) for r in earlier[-50:] if len(r) > k]
    if not others or any(o is None for o in others):
        return
    column = f"column {k + 1}" + (f" ({names[k]!r})" if names is not None and k < len(names) else "")
    if last is None:  # a sign, a point or an 'e' alone
        raise error(path, line, f"{column}: the file ends inside a number: {tokens[k]!r} (truncated file?)")
    what = ("decimals", "significant digits", "exponent digits")
    # a fixed format writes every number with the same decimals and exponent digits (%.4f, %.6e);
    # '%g' or hand-typed numbers vary in them, and their last number is judged only in a long file
    fixed_format = len({(o[0], o[2]) for o in others}) == 1
    # a zero has no significant digits and '%g' writes it without an exponent: only its decimals tell
    try:
        zero = float(tokens[k].strip().replace(",", ".")) == 0.0
    except ValueError:  # '1.5e', '2e-': cut inside the exponent
        zero = False
    for i in ((0,) if zero else range(3)):
        written = np.array([o[i] for o in others])
        more = int(np.sum(written > last[i]))
        if fixed_format and more == written.size and np.all(written == written[0]):  # cut short
            where = f"every earlier row has {written[0]}"
        elif written.size >= 10 and more >= 0.95 * written.size:  # a long export, cut short
            where = f"{more} of the {written.size} rows before it have more"
        else:
            continue
        raise error(path, line, f"{column}: the file ends inside a number: {tokens[k]!r} has {last[i]} {what[i]} "
                                f"where {where} (truncated file?; if the row is complete, end it with a line break)")


def refuse_short_last_block(path, outer, inner, last_line: int, outer_name: str = "angle", outer_unit: str = "deg",
                            inner_name: str = "wavelength", inner_unit: str = "nm") -> None:
    """Refuse a file cut inside its last block: the points (``outer``, ``inner``) in file order
    (e.g. angle, wavelength), grouped by ``outer``; when every other group holds the same set of
    ``inner`` values and the group of the file's last row holds only the first of them, in the
    file's order, the file was cut (one angle would silently cover a part of the range)."""
    outer = np.round(np.asarray(outer, dtype=float), 9)
    inner = np.round(np.asarray(inner, dtype=float), 9)
    if outer.size < 2:
        return
    keys, first = np.unique(outer, return_index=True)
    if keys.size < 2:
        return
    order = keys[np.argsort(first)]
    last_key = outer[-1]
    if last_key != order[-1]:
        return
    groups = {k: inner[outer == k] for k in order}
    others = [groups[k] for k in order[:-1]]
    ref = others[0]
    if any(g.size != ref.size or not np.array_equal(np.sort(g), np.sort(ref)) for g in others[1:]):
        return
    last = groups[last_key]
    if last.size >= ref.size or not np.array_equal(last, ref[: last.size]):
        return
    label = f"{outer_name} {last_key:g}" + (f" {outer_unit}" if outer_unit else "")
    raise error(
        path, last_line,
        f"the file ends inside the block of {label}: {last.size} rows ({inner_name} {last.min():g}–{last.max():g} "
        f"{inner_unit}) where every other {outer_name} has {ref.size} ({inner_name} {ref.min():g}–{ref.max():g} "
        f"{inner_unit}): truncated file?",
    )


# ---------------------------------------------------------------------------------------------
# the registry record: one per format module
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Head:
    """The start of a file, as the sniffing tests see it."""

    #: the file
    path: Path
    #: its first 8 KiB
    raw: bytes
    #: its first 12 non-blank lines, stripped, decoded as Latin-1 (never fails)
    lines: tuple[str, ...]

    @classmethod
    def of(cls, path) -> "Head":
        path = Path(path)
        if not path.is_file():
            raise LayerstackError(f"{path}: no such file")
        with open(path, "rb") as fh:
            raw = fh.read(8192)
        lines = tuple(ln.strip() for ln in raw.decode("latin-1").splitlines() if ln.strip())[:12]
        return cls(path, raw, lines)


@dataclass(frozen=True)
class Format:
    """A file format: what :func:`~layerstack_jax.io.sniff_format` answers, the reader
    :func:`~layerstack_jax.io.read_measurement` calls, and the test on the file's start that
    recognizes it (tests are asked in the order of ``FORMATS`` in the package ``__init__``)."""

    #: the name (``Measurement.file_format``)
    name: str
    #: ``read(path, **options) -> Measurement``
    read: Callable[..., Measurement]
    #: ``sniff(head) -> bool``: True when the file is in this format
    sniff: Callable[[Head], bool]
