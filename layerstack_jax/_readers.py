r"""Readers of instrument files: one function per format, and :func:`read_measurement` that sniffs it.

Every reader returns a :class:`~layerstack_jax._measurement.Measurement` in the library's units
(wavelength in nm, angles in degrees, reflectance/transmittance as fractions) with ψ, Δ and
Mueller elements **as the instrument reports them** (``delta_convention="instrument"``, the
convention of Woollam, Sentech and Accurion instruments and of pyElli/refellips, which is the
library's public one). Only units are converted; Δ is not re-wrapped.

Formats
-------
* :func:`read_woollam` — J.A. Woollam WVASE / CompleteEASE ASCII exports (``.dat``): a title
  line, optional ``VASEmethod[...]``/``Original[...]`` lines, a wavelength-unit line (``nm``,
  ``Angstroms``, ``eV``, ``um``), then rows ``wavelength angle psi delta [sigma_psi sigma_delta]``
  (WVASE) or the same prefixed by ``E`` (CompleteEASE); rows labelled ``dPolE`` (depolarization, %),
  ``uR`` … are kept in ``Measurement.extras``; rows ``mm12 wavelength angle value sigma`` (``mmij``,
  i, j = 1..4) make a Mueller-matrix measurement normalised by M11 (this row layout follows
  CompleteEASE's labelled-row convention; no real Mueller export was at hand to test it).
  Time-resolved ("Dynamic") and tan ψ / cos Δ ("TRIG") exports are refused.
* :func:`read_sentech` — Sentech SpectraRay ASCII exports: a first line
  ``; WAVELENGTH a1 a1 a2 a2 …`` (the angle of every column), then rows ``wavelength(nm)`` followed
  by ψ, Δ pairs per angle, or by the 16 elements M11 … M44 (row-major) of the normalised Mueller
  matrix per angle.
* :func:`read_accurion` — Accurion EP3/EP4 nulling-ellipsometer exports (``#Lambda … AOI Delta
  Psi`` header, a ``#nm … deg`` units line); the nulling zones 1–4 of one point are averaged
  (as refellips does), no σ.
* :func:`read_nexus` — NeXus/HDF5 files following the NXellipsometry application definition
  (both layouts found in the wild: ``entry/sample/measured_data`` with
  ``entry/instrument/spectrometer/wavelength``, and ``entry/data_collection/measured_data`` with
  ``wavelength_spectrum`` and ``data_error``); ψ/Δ data only. Needs ``h5py``.
* :func:`read_jcamp` — JCAMP-DX reflectance / transmittance spectra (parsed by the ``jcamp``
  package); x in nm, µm or cm⁻¹; absorbance spectra are refused.
* :func:`read_measurement_csv` — plain delimited text (comma, semicolon, tab or blanks; quoted
  headers as R and Excel write them) and the measurement CSV written by
  :func:`write_measurement_csv` (round trip exact).

Errors: every problem raises :class:`~layerstack_jax.LayerstackError` naming the file, the line
(or HDF5 dataset) and why.
"""

from __future__ import annotations

import csv
import io as _io
import json
import math
import re
import warnings
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from ._measurement import QUANTITIES, Measurement, component_names, measurement_from_points
from ._validate import LayerstackError

__all__ = [
    "read_measurement",
    "read_woollam",
    "read_sentech",
    "read_accurion",
    "read_nexus",
    "read_jcamp",
    "read_measurement_csv",
    "write_measurement_csv",
    "sniff_format",
    "wavelength_to_nm",
]

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


def _unit(text: str) -> Optional[str]:
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
    canon = _unit(unit) or unit
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


def _error(path, line: Optional[int], why: str) -> LayerstackError:
    where = f"{path}, line {line}" if line is not None else f"{path}"
    return LayerstackError(f"{where}: {why}")


def _read_text(path) -> list[str]:
    """Lines of a text file (UTF-8, else Latin-1 as instruments on Windows write), without line ends."""
    path = Path(path)
    if not path.is_file():
        raise LayerstackError(f"{path}: no such file")
    raw = path.read_bytes()
    if b"\x00" in raw[:4096]:
        raise _error(path, None, "binary file, not a text export (for NeXus/HDF5 use read_nexus)")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")
    return text.replace("\x1a", "").splitlines()


def _float(token: str) -> Optional[float]:
    """The number a token spells (``1.5``, ``-3e-2``, ``inf``, ``nan``), or None."""
    try:
        return float(token)
    except ValueError:
        return None


def _numbers(tokens: Sequence[str]) -> Optional[list[float]]:
    out = [_float(t) for t in tokens]
    return None if any(v is None for v in out) else out


def _check_range(path, line, name: str, value: float, lo: float, hi: float, unit: str = "degrees") -> None:
    if not (math.isfinite(value) and lo <= value <= hi):
        raise _error(path, line, f"{name} = {value!r} is not a number in [{lo:g}, {hi:g}] {unit}")


def _warn_implausible(path, m: Measurement) -> Measurement:
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


def _check_angle(path, line, value: float) -> None:
    _check_range(path, line, "angle of incidence", value, 0.0, 90.0)
    if value >= 90.0:
        raise _error(path, line, f"angle of incidence = {value!r} must be below 90 degrees")


# ---------------------------------------------------------------------------------------------
# Woollam WVASE / CompleteEASE
# ---------------------------------------------------------------------------------------------
_MUELLER_LABEL = re.compile(r"^m{1,2}([1-4])([1-4])$", re.IGNORECASE)
_PSI_DELTA_LABELS = {"e"}
_HEADER_COLUMN_WORDS = {"aoi", "psi", "delta", "angle", "ψ", "δ"}


def _woollam_unit_line(tokens: list[str]) -> Optional[str]:
    """The unit of a Woollam unit line (``nm``, ``Angstroms``, ``eV``; refellips-style
    ``nm  AOI  Psi  Delta`` too), or None when the line is not one."""
    if not tokens or _unit(tokens[0]) is None or _unit(tokens[0]) == "1/cm":
        return None
    rest = {t.lower() for t in tokens[1:]}
    if rest <= _HEADER_COLUMN_WORDS or "trig" in rest:
        return _unit(tokens[0])
    return None


def read_woollam(path) -> Measurement:
    """Read a J.A. Woollam WVASE or CompleteEASE ASCII export (ψ, Δ with σ; or Mueller elements).

    Args:
        path: the ``.dat``/``.txt`` file (format: module docstring).

    Returns:
        :class:`Measurement` with ``quantity="psi_delta"`` (``values (ang, 2, wl)`` in degrees,
        ``sigma`` where the rows have 6 numbers) or ``"mueller"`` (``mmij`` rows; ``(ang, 4, 4, wl)``,
        M11 = 1), wavelengths converted to nm; ``dPolE``/``uR``/other labelled rows in ``extras``;
        ``metadata``: ``title`` (first line), ``method`` (``VASEmethod[...]``), ``wavelength_unit``.

    Raises:
        LayerstackError: naming the file, the line and why (no unit line, a row with the wrong
        number of fields or a non-number, ψ outside [0°, 90°], an angle outside [0°, 90°),
        time-resolved or TRIG exports, no data).
    """
    lines = _read_text(path)
    header: list[tuple[int, str]] = []
    unit = None
    start = None
    for i, line in enumerate(lines, start=1):
        tokens = line.split()
        if not tokens:
            continue
        numeric_row = len(tokens) >= 2 and _numbers(tokens) is not None
        labelled_row = len(tokens) >= 3 and tokens[0][:1].isalpha() and _numbers(tokens[1:]) is not None
        if unit is not None and (numeric_row or labelled_row):
            start = i
            break
        if {t.lower() for t in tokens} & {"trig"}:
            raise _error(path, i, "tan(psi)/cos(delta) ('TRIG') exports are not supported; export psi/delta instead")
        if tokens[0].lower() == "dynamic":
            raise _error(path, i, "time-resolved ('Dynamic') exports are not supported; export one time slice")
        u = _woollam_unit_line(tokens)
        if u is not None:
            unit = u
        header.append((i, line.strip()))
    if unit is None:
        raise _error(
            path, None, "no wavelength-unit line ('nm', 'Angstroms', 'eV' or 'um') before the data: not a Woollam export"
        )
    if start is None:
        raise _error(path, len(lines), "no data rows after the header")

    pd_rows: list[tuple[int, list[float]]] = []
    mm_rows: dict[str, list[tuple[int, list[float]]]] = {}
    extras: dict[str, list[list[float]]] = {}
    for i in range(start, len(lines) + 1):
        tokens = lines[i - 1].split()
        if not tokens:
            continue
        label = None
        if _float(tokens[0]) is None:
            label, tokens = tokens[0], tokens[1:]
        nums = _numbers(tokens)
        if nums is None:
            bad = next(t for t in tokens if _float(t) is None)
            raise _error(path, i, f"{bad!r} is not a number")
        if label is None or label.lower() in _PSI_DELTA_LABELS:
            if len(nums) not in (4, 6):
                raise _error(
                    path,
                    i,
                    f"expected 4 or 6 numbers (wavelength, angle, psi, delta[, sigma_psi, sigma_delta]), got {len(nums)}"
                    + (" (truncated file?)" if i == len(lines) else ""),
                )
            _check_angle(path, i, nums[1])
            _check_range(path, i, "psi", nums[2], 0.0, 90.0)
            _check_range(path, i, "delta", nums[3], -360.0, 360.0)
            pd_rows.append((i, nums))
        else:
            if len(nums) != 4:
                raise _error(
                    path,
                    i,
                    f"a {label!r} row needs 4 numbers (wavelength, angle, value, sigma), got {len(nums)}"
                    + (" (truncated file?)" if i == len(lines) else ""),
                )
            m = _MUELLER_LABEL.match(label)
            if m:
                _check_angle(path, i, nums[1])
                _check_range(path, i, label, nums[2], -1.5, 1.5, unit="(normalised Mueller element)")
                mm_rows.setdefault(f"M{m.group(1)}{m.group(2)}", []).append((i, nums))
            else:
                label = "dPolE" if label.lower() == "dpole" else label
                extras.setdefault(label, []).append(nums)
    if pd_rows and any(len(r) != len(pd_rows[0][1]) for _, r in pd_rows):
        i = next(i for i, r in pd_rows if len(r) != len(pd_rows[0][1]))
        raise _error(path, i, "rows mix 4 and 6 numbers (with and without sigma)")

    title = header[0][1] if header and not header[0][1].lower().startswith("vasemethod") else ""
    meta = [("title", title)]
    meta += [("method", h) for _, h in header if h.lower().startswith("vasemethod")]
    meta += [("original", h) for _, h in header if h.lower().startswith("original")]
    meta.append(("wavelength_unit", unit))
    ext = {k: np.column_stack([wavelength_to_nm(np.array(v)[:, 0], unit), np.array(v)[:, 1:]]) for k, v in extras.items()}
    fields = dict(file_format="woollam", source=str(path), delta_convention="instrument")
    where = str(path)
    if pd_rows:
        a = np.array([r for _, r in pd_rows])
        for key, rows in mm_rows.items():
            ext[key] = np.array([[wavelength_to_nm(r[0], unit), *r[1:]] for _, r in rows])
        sigma = {"psi": a[:, 4], "delta": a[:, 5]} if a.shape[1] == 6 else None
        return measurement_from_points(
            "psi_delta",
            a[:, 1],
            wavelength_to_nm(a[:, 0], unit),
            {"psi": a[:, 2], "delta": a[:, 3]},
            sigma=sigma,
            extras=ext,
            where=where,
            metadata=tuple(meta),
            **fields,
        )
    if mm_rows:
        return _woollam_mueller(path, mm_rows, unit, ext, meta, fields)
    raise _error(path, len(lines), "no psi/delta ('E') or Mueller ('mmij') rows")


def _woollam_mueller(path, mm_rows, unit, ext, meta, fields) -> Measurement:
    """Mueller elements from ``mmij`` rows on one grid (M11 = 1 where the file omits it)."""
    names = component_names("mueller")
    first = next(iter(mm_rows.values()))
    ang = np.array([r[1] for _, r in first])
    wl = np.array([r[0] for _, r in first])
    comps, sig = {}, {}
    for name in names:
        rows = mm_rows.get(name)
        if rows is None:
            if name != "M11":
                raise _error(path, None, f"Mueller export without {name.lower().replace('m', 'mm', 1)} rows")
            comps[name], sig[name] = np.ones_like(ang), np.zeros_like(ang)
            continue
        r = np.array([x for _, x in rows])
        if r.shape[0] != ang.size or not (np.array_equal(r[:, 1], ang) and np.array_equal(r[:, 0], wl)):
            raise _error(path, rows[0][0], f"{name} rows are not on the wavelengths and angles of the other elements")
        comps[name], sig[name] = r[:, 2], r[:, 3]
    return measurement_from_points(
        "mueller",
        ang,
        wavelength_to_nm(wl, unit),
        comps,
        sigma=sig,
        extras=ext,
        where=str(path),
        mueller_normalized=True,
        metadata=tuple(meta),
        **fields,
    )


# ---------------------------------------------------------------------------------------------
# Sentech SpectraRay
# ---------------------------------------------------------------------------------------------
def _sentech_numbers(path, i, tokens: list[str]) -> list[float]:
    out = []
    for t in tokens:
        v = _float(t)
        if v is None and "," in t and "." not in t:  # decimal comma (German locale exports)
            v = _float(t.replace(",", "."))
        if v is None:
            raise _error(path, i, f"{t!r} is not a number")
        out.append(v)
    return out


def read_sentech(path) -> Measurement:
    """Read a Sentech SpectraRay ASCII export of ψ/Δ or of the normalised Mueller matrix.

    Args:
        path: the ``.txt`` file: first line ``; WAVELENGTH a1 a1 a2 a2 …`` (one angle per value
            column), then one row per wavelength (nm): ψ, Δ per angle, or M11 … M44 (row-major)
            per angle. Decimal commas are accepted.

    Returns:
        :class:`Measurement`: ``"psi_delta"`` ``(ang, 2, wl)`` degrees, Δ as reported (SpectraRay:
        0°–360°), or ``"mueller"`` ``(ang, 4, 4, wl)`` (``mueller_normalized`` when every M11 is 1).
        No σ (the export has none).

    Raises:
        LayerstackError: first line not a SpectraRay header, columns not matching the header's
        angles, a non-number, ψ outside [0°, 90°] (file and line named).
    """
    lines = _read_text(path)
    if not lines or not lines[0].lstrip().startswith(";"):
        raise _error(path, 1, "not a SpectraRay export: the first line must be '; WAVELENGTH <angle per column> …'")
    head = lines[0].lstrip()[1:].split()
    if not head or head[0].lower() != "wavelength":
        got = head[0] if head else "nothing"
        raise _error(path, 1, f"first column is {got!r}; only wavelength (nm) exports are supported")
    angles = _sentech_numbers(path, 1, head[1:])
    n = len(angles)
    if n == 0:
        raise _error(path, 1, "the header names no angle columns")
    for a in angles:
        _check_angle(path, 1, a)
    rows, row_lines = [], []
    for i, line in enumerate(lines[1:], start=2):
        tokens = line.split()
        if not tokens:
            continue
        nums = _sentech_numbers(path, i, tokens)
        if len(nums) != n + 1:
            raise _error(
                path,
                i,
                f"expected {n + 1} numbers (wavelength and the {n} columns of the header), got {len(nums)}"
                + (" (truncated file?)" if i == len(lines) else ""),
            )
        rows.append(nums)
        row_lines.append(i)
    if not rows:
        raise _error(path, len(lines), "no data rows")
    a = np.array(rows)
    wl = a[:, 0]
    vals = a[:, 1:]
    ang_cols = np.array(angles)
    blocks16 = n % 16 == 0 and all(np.all(ang_cols[k : k + 16] == ang_cols[k]) for k in range(0, n, 16))
    is_mueller = blocks16 and np.allclose(vals[:, ::16], 1.0)
    meta = (("wavelength_unit", "nm"), ("header", lines[0].strip()))
    fields = dict(file_format="sentech", source=str(path), delta_convention="instrument", metadata=meta)
    if is_mueller:
        names = component_names("mueller")
        angs = ang_cols[::16]
        comps = {nm: vals[:, k::16].T.ravel() for k, nm in enumerate(names)}
        return _warn_implausible(path, measurement_from_points(
            "mueller", np.repeat(angs, wl.size), np.tile(wl, angs.size), comps,
            where=str(path), mueller_normalized=True, **fields,
        ))
    if n % 2 or np.any(ang_cols[0::2] != ang_cols[1::2]):
        raise _error(path, 1, "psi/delta exports need the angles in pairs (psi, delta) per angle; got " + " ".join(head[1:]))
    angs = ang_cols[0::2]
    psi, delta = vals[:, 0::2], vals[:, 1::2]
    bad = np.argwhere(~((psi >= 0) & (psi <= 90)))
    if bad.size:
        r, c = bad[0]
        raise _error(path, row_lines[r], f"psi = {float(psi[r, c])!r} is not in [0, 90] degrees")
    return measurement_from_points(
        "psi_delta", np.repeat(angs, wl.size), np.tile(wl, angs.size),
        {"psi": psi.T.ravel(), "delta": delta.T.ravel()}, where=str(path), **fields,
    )


# ---------------------------------------------------------------------------------------------
# Accurion EP3/EP4
# ---------------------------------------------------------------------------------------------
def read_accurion(path) -> Measurement:
    """Read an Accurion EP3/EP4 nulling-ellipsometer export (``.dat``/``.ds.dat``).

    Args:
        path: tab-separated file; a header line ``#Lambda Bandwidth AOI Delta Psi …`` (any order)
            and a units line ``#nm nm deg deg deg …``; one row per nulling zone and point.

    Returns:
        :class:`Measurement` ``"psi_delta"``: ψ and Δ (degrees, as reported) averaged over the
        nulling zones 1–4 measured at the same wavelength and angle, leaving out zones reported as
        NaN (``metadata["zones_averaged"]`` gives the largest count); where no zone 1–4 row is
        finite, the instrument's zone-0 average; zone-5 rows (a spread) are not used; no σ.

    Raises:
        LayerstackError: missing columns, units other than nm/deg, several regions of interest,
        rows with the wrong number of fields (file and line named).
    """
    lines = _read_text(path)
    comments = [(i, ln) for i, ln in enumerate(lines, start=1) if ln.startswith("#")]
    if len(comments) < 2:
        raise _error(path, 1, "not an Accurion export: expected a '#' header line and a '#' units line")
    (hi, hline), (ui, uline) = comments[0], comments[1]
    names = [t.strip().lower() for t in hline.lstrip("#").split("\t")]
    units = [t.strip() for t in uline.lstrip("#").split("\t")]
    col = {name: k for k, name in enumerate(names)}
    for need in ("lambda", "aoi", "delta", "psi"):
        if need not in col:
            raise _error(path, hi, f"no {need!r} column in the header ({', '.join(names)})")
    lam_unit = units[col["lambda"]] if col["lambda"] < len(units) else ""
    if _unit(lam_unit) is None:
        raise _error(path, ui, f"wavelength unit {lam_unit!r} not understood")
    for need in ("aoi", "delta", "psi"):
        u = units[col[need]] if col[need] < len(units) else ""
        if u.lower() not in ("deg", "degree", "degrees", "°"):
            raise _error(path, ui, f"column {need!r} is in {u!r}; degrees expected")
    roi = col.get("roiidx")
    zone = col.get("zone")
    rows = []
    for i, line in enumerate(lines, start=1):
        if line.startswith("#") or not line.strip():
            continue
        tokens = line.split("\t")
        if len(tokens) < len(names):
            why = f"expected {len(names)} tab-separated fields, got {len(tokens)}"
            raise _error(path, i, why + (" (truncated file?)" if i == len(lines) else ""))
        try:
            r = [float(tokens[col[k]]) for k in ("lambda", "aoi", "psi", "delta")]
            r.append(float(tokens[roi]) if roi is not None else 0.0)
            r.append(float(tokens[zone]) if zone is not None else 1.0)
        except ValueError:
            raise _error(path, i, "lambda, AOI, psi, delta must be numbers") from None
        _check_angle(path, i, r[1])
        if not (math.isnan(r[2]) and math.isnan(r[3])):  # NaN, NaN: a zone that did not null
            _check_range(path, i, "psi", r[2], 0.0, 90.0)
            _check_range(path, i, "delta", r[3], -360.0, 360.0)
        rows.append(r)
    if not rows:
        raise _error(path, len(lines), "no data rows")
    a = np.array(rows)
    if np.unique(a[:, 4]).size > 1:
        raise _error(path, None, f"the file holds {np.unique(a[:, 4]).size} regions of interest (ROIidx); export one")
    # Zones 1-4 are the four nulling zones; zone 0 is the instrument's average of them, zone 5
    # (no polarizer/analyser angles) a spread: average the finite zones 1-4, else take zone 0.
    in14 = (a[:, 5] >= 1) & (a[:, 5] <= 4)
    key_all = np.round(a[:, :2], 9)
    has14 = {tuple(k) for k in key_all[in14 & np.isfinite(a[:, 2]) & np.isfinite(a[:, 3])]}
    use = in14 | ((a[:, 5] == 0) & np.array([tuple(k) not in has14 for k in key_all]))
    a = a[use]
    wl = wavelength_to_nm(a[:, 0], lam_unit)
    keys, inverse, counts = np.unique(np.round(np.c_[a[:, 1], wl], 9), axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    ok = np.isfinite(a[:, 2]) & np.isfinite(a[:, 3])
    total = np.zeros((keys.shape[0], 2))
    np.add.at(total, inverse[ok], a[ok, 2:4])
    n_ok = np.bincount(inverse[ok], minlength=keys.shape[0])
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = total / n_ok[:, None]  # NaN where no zone nulled
    first = np.zeros(keys.shape[0], dtype=int)
    first[inverse[::-1]] = np.arange(a.shape[0])[::-1]
    meta = (("header", hline.strip()), ("units", uline.strip()), ("zones_averaged", str(int(n_ok.max()))))
    return measurement_from_points(
        "psi_delta", a[first, 1], wl[first], {"psi": mean[:, 0], "delta": mean[:, 1]},
        where=str(path), file_format="accurion", source=str(path), delta_convention="instrument", metadata=meta,
    )


# ---------------------------------------------------------------------------------------------
# NeXus / HDF5 (NXellipsometry)
# ---------------------------------------------------------------------------------------------
def _h5_text(x) -> str:
    v = x[()]
    if isinstance(v, bytes):
        return v.decode("utf-8", "replace")
    if isinstance(v, np.ndarray):
        return ", ".join(s.decode("utf-8", "replace") if isinstance(s, bytes) else str(s) for s in v.ravel())
    return str(v)


def _h5_units(ds) -> str:
    for key in ("units", "unit"):
        if key in ds.attrs:
            u = ds.attrs[key]
            return u.decode() if isinstance(u, bytes) else str(u)
    return ""


def read_nexus(path, *, entry: str = "entry") -> Measurement:
    """Read ψ/Δ from a NeXus/HDF5 file following the NXellipsometry application definition.

    Args:
        path: the ``.nxs``/``.h5`` file.
        entry: name of the NXentry group (default ``"entry"``).

    Returns:
        :class:`Measurement` ``"psi_delta"``: ``measured_data`` ``(ang, 2, wl)`` (leading length-1
        axes dropped), σ from ``data_error`` when numeric, wavelengths converted from the dataset's
        ``units`` attribute (Å, nm, µm, eV) to nm, angles from ``instrument/angle_of_incidence``;
        ``metadata``: sample name, layer structure, description, instrument, definition version.

    Raises:
        LayerstackError: not an HDF5 file, a missing dataset (its path named), a data type other
        than psi/delta, shapes that do not match.
    """
    try:
        import h5py
    except ImportError as err:  # pragma: no cover - depends on the environment
        raise LayerstackError("reading NeXus files needs h5py: pip install 'layerstack-jax[readers]'") from err
    try:
        f = h5py.File(path, "r")
    except OSError as err:
        raise _error(path, None, f"not an HDF5/NeXus file ({err})") from None
    with f:
        if entry not in f:
            raise _error(path, None, f"no NXentry group {entry!r} (groups: {', '.join(f.keys())})")
        e = f[entry]
        if "data_collection/measured_data" in e:
            keys = ("measured_data", "wavelength_spectrum", "data_type", "data_error")
            data_p, wl_p, type_p, err_p = (f"data_collection/{k}" for k in keys)
        else:  # the legacy layout of NXellipsometry 0.0.2 files
            data_p, wl_p = "sample/measured_data", "instrument/spectrometer/wavelength"
            type_p, err_p = "sample/data_type", "sample/data_error"
        for p in (data_p, wl_p, "instrument/angle_of_incidence"):
            if p not in e:
                raise _error(path, None, f"dataset /{entry}/{p} missing (NXellipsometry requires it)")
        data_type = _h5_text(e[type_p]) if type_p in e else "psi/delta"
        if not re.fullmatch(r"\s*psi\s*/\s*delta\s*", data_type, re.IGNORECASE):
            raise _error(path, None, f"/{entry}/{type_p} is {data_type!r}; only psi/delta data are supported")
        wl_ds = e[wl_p]
        wl_unit = _h5_units(wl_ds)
        if _unit(wl_unit) is None:
            raise _error(path, None, f"/{entry}/{wl_p} has units {wl_unit!r}; expected angstrom, nm, um or eV")
        wl = wavelength_to_nm(np.asarray(wl_ds, dtype=float).ravel(), wl_unit)
        ang_ds = e["instrument/angle_of_incidence"]
        ang = np.atleast_1d(np.asarray(ang_ds, dtype=float)).ravel()
        ang_unit = _h5_units(ang_ds).lower()
        if ang_unit.startswith("rad"):
            ang = np.rad2deg(ang)
        data = np.asarray(e[data_p], dtype=float)
        while data.ndim > 3 and data.shape[0] == 1:
            data = data[0]
        if data.shape != (ang.size, 2, wl.size):
            raise _error(
                path,
                None,
                f"/{entry}/{data_p} has shape {np.shape(e[data_p])}; "
                f"expected (angle, 2, wavelength) = {(ang.size, 2, wl.size)}",
            )
        sigma = None
        if err_p in e and np.issubdtype(e[err_p].dtype, np.number):
            sigma = np.asarray(e[err_p], dtype=float)
            while sigma.ndim > 3 and sigma.shape[0] == 1:
                sigma = sigma[0]
            if sigma.shape != data.shape:
                raise _error(path, None, f"/{entry}/{err_p} has shape {sigma.shape}, measured_data {data.shape}")
        meta = [("wavelength_unit", wl_unit)]
        for key in ("definition", "experiment_description", "sample/sample_name", "sample/layer_structure",
                    "instrument/company", "instrument/model", "start_time"):
            if key in e and isinstance(e[key], h5py.Dataset):
                meta.append((key.split("/")[-1], _h5_text(e[key])))
    for a in ang:
        _check_angle(path, None, float(a))
    order = np.argsort(wl)
    if np.any(np.diff(wl[order]) <= 0):
        raise _error(path, None, f"/{entry}/{wl_p} has repeated wavelengths")
    return Measurement(
        quantity="psi_delta",
        angles_deg=ang,
        wavelength_nm=wl[order],
        values=data[..., order],
        sigma=None if sigma is None else sigma[..., order],
        delta_convention="instrument",
        file_format="nexus",
        source=str(path),
        metadata=tuple(meta),
    )


# ---------------------------------------------------------------------------------------------
# JCAMP-DX
# ---------------------------------------------------------------------------------------------
_JCAMP_QUANTITY = {
    "transmittance": ("transmittance", False),
    "transmission": ("transmittance", False),
    "%t": ("transmittance", True),
    "%transmittance": ("transmittance", True),
    "percent transmittance": ("transmittance", True),
    "reflectance": ("reflectance", False),
    "reflection": ("reflectance", False),
    "%r": ("reflectance", True),
    "%reflectance": ("reflectance", True),
    "percent reflectance": ("reflectance", True),
}


def read_jcamp(path, *, angle_deg: Optional[float] = None, percent: Optional[bool] = None) -> Measurement:
    """Read a JCAMP-DX reflectance or transmittance spectrum (parsed with the ``jcamp`` package).

    Args:
        path: the ``.jdx``/``.dx`` file (one spectrum; AFFN, packed or compressed data).
        angle_deg: angle of incidence in degrees (JCAMP-DX has no field for it): required.
        percent: ``True`` when the values are in % although ``##YUNITS`` says TRANSMITTANCE /
            REFLECTANCE (common in instrument exports); ``None`` (default) follows ``##YUNITS`` and
            refuses values above 1.5 as a probable percent scale.

    Returns:
        :class:`Measurement` ``"reflectance"`` or ``"transmittance"`` ``(1, wl)`` (fractions),
        wavelengths converted from ``##XUNITS`` (nm, µm, 1/cm) to nm and sorted increasing.

    Raises:
        LayerstackError: not JCAMP-DX, absorbance or other y units, x units that are not a
        wavelength, no ``##END=`` or fewer points than ``##NPOINTS`` (truncated), percent values
        in a fraction file, no ``angle_deg``.
    """
    try:
        import jcamp
    except ImportError as err:  # pragma: no cover - depends on the environment
        raise LayerstackError("reading JCAMP-DX files needs jcamp: pip install 'layerstack-jax[readers]'") from err
    lines = _read_text(path)
    first = next(((i, ln) for i, ln in enumerate(lines, start=1) if ln.strip()), (1, ""))
    if not first[1].lstrip().startswith("##"):
        raise _error(path, first[0], "not a JCAMP-DX file: the first line must be a '##LABEL=' record")
    if not any(ln.strip().upper().startswith("##END") for ln in lines):
        raise _error(path, len(lines), "the file ends without '##END=' (truncated?)")
    if sum(ln.strip().upper().startswith("##TITLE") for ln in lines) > 1:
        raise _error(path, None, "a compound (LINK) JCAMP-DX file with several blocks; export one spectrum per file")
    try:
        d = jcamp.read(_io.StringIO("\n".join(lines)))
    except Exception as err:  # the jcamp parser raises bare Exceptions on corrupt data
        raise _error(path, None, f"JCAMP-DX data could not be parsed ({err})") from None
    yunits = str(d.get("yunits", "")).strip()
    key = " ".join(yunits.lower().split())
    key = key.replace(" ", "") if key.replace(" ", "") in _JCAMP_QUANTITY else key
    y_line = next((i for i, ln in enumerate(lines, start=1) if ln.upper().startswith("##YUNITS")), None)
    x_line = next((i for i, ln in enumerate(lines, start=1) if ln.upper().startswith("##XUNITS")), None)
    if key not in _JCAMP_QUANTITY:
        why = f"##YUNITS= {yunits!r}: only reflectance or transmittance spectra can be read (not absorbance or counts)"
        raise _error(path, y_line, why)
    quantity, pct = _JCAMP_QUANTITY[key]
    xunits = str(d.get("xunits", "")).strip()
    if _unit(xunits) is None:
        raise _error(path, x_line, f"##XUNITS= {xunits!r} is not a wavelength unit (NANOMETERS, MICROMETERS, 1/CM)")
    x = np.asarray(d.get("x", []), dtype=float)
    y = np.asarray(d.get("y", []), dtype=float)
    npoints = d.get("npoints")
    if x.size == 0 or (npoints is not None and x.size != int(npoints)):
        raise _error(path, None, f"##NPOINTS= {npoints} but {x.size} values were read (truncated?)")
    if percent is not None:
        pct = percent
    if pct:
        y = y / 100.0
    elif np.nanmax(y) > 1.5:
        raise _error(
            path, y_line,
            f"##YUNITS= {yunits} but the values reach {np.nanmax(y):g}: a fraction cannot; "
            "if the file is in percent, pass percent=True",
        )
    if angle_deg is None:
        raise _error(path, None, "JCAMP-DX gives no angle of incidence: pass angle_deg= (e.g. 0 for normal incidence)")
    _check_angle(path, None, float(angle_deg))
    wl = wavelength_to_nm(x, xunits)
    order = np.argsort(wl)
    wl, y = wl[order], y[order]
    if np.any(np.diff(wl) <= 0):
        raise _error(path, None, "repeated x values")
    meta = tuple(
        (k, str(d[k]))
        for k in ("title", "datatype", "data type", "origin", "owner", "spectrometer/data system", "xunits", "yunits")
        if k in d
    ) + (("angle_source", "given by the caller"), ("percent", str(bool(pct))))
    return _warn_implausible(path, Measurement(
        quantity=quantity,
        angles_deg=np.array([float(angle_deg)]),
        wavelength_nm=wl,
        values=y[None, :],
        file_format="jcamp",
        source=str(path),
        metadata=meta,
    ))


# ---------------------------------------------------------------------------------------------
# CSV: plain tables and the measurement CSV (round trip)
# ---------------------------------------------------------------------------------------------
_MAGIC = "# layerstack measurement csv v1"


def _split_header_name(raw: str) -> tuple[str, str]:
    """``'Wavelength (nm)'`` → ``('wavelength', 'nm')``; ``'wavelength_um'`` → ``('wavelength', 'um')``;
    ``'%R'``/``'R [%]'`` → ``('r', '%')``."""
    s = raw.strip().strip('"').strip("'").strip()
    unit = ""
    m = re.search(r"[\(\[]\s*([^\)\]]*)\s*[\)\]]\s*$", s)
    if m:
        unit, s = m.group(1).strip(), s[: m.start()].strip()
    if s.startswith("%"):
        unit, s = "%", s[1:].strip()
    if s.endswith("%"):
        unit, s = "%", s[:-1].strip()
    name = s.lower().replace("ψ", "psi").replace("δ", "delta").replace("θ", "theta").replace("λ", "lambda")
    name = re.sub(r"[\s\-]+", "_", name)
    if not unit:
        m = re.match(r"^(.*?)_(nm|um|µm|μm|ev|a|angstroms?|deg|degrees|rad|percent|pct|cm\-?1|1/cm)$", name)
        if m:
            name, unit = m.group(1), m.group(2)
    if unit.lower() in ("percent", "pct"):
        unit = "%"
    return name, unit.strip()


_WAVELENGTH_NAMES = {"wavelength", "wave_length", "lambda", "wl", "wvl", "energy", "photon_energy", "wavenumber"}
_ANGLE_NAMES = {"angle", "aoi", "angle_of_incidence", "incidence_angle", "theta", "angle_deg"}
_SIGMA = re.compile(r"^(?:sigma|err|error|std|uncertainty|d)_?(.+)$|^(.+?)_?(?:sigma|err|error|std|uncertainty)$")


def _column_role(name: str, unit: str):
    """(role, component) of a CSV column: ('wavelength', None), ('angle', None), ('value', comp),
    ('sigma', comp) or (None, None)."""

    def comp_of(n):
        if n in ("psi",):
            return "psi"
        if n in ("delta",):
            return "delta"
        if n in ("r", "reflectance", "reflection", "specular_reflectance", "refl"):
            return "R"
        if n in ("t", "transmittance", "transmission", "trans"):
            return "T"
        m = re.fullmatch(r"m{1,2}([1-4])([1-4])", n)
        if m:
            return f"M{m.group(1)}{m.group(2)}"
        return None

    if name in _WAVELENGTH_NAMES or (not name and _unit(unit)) or (_unit(name) is not None and not unit):
        return "wavelength", None
    if name in _ANGLE_NAMES:
        return "angle", None
    c = comp_of(name)
    if c is not None:
        return "value", c
    m = _SIGMA.match(name)
    if m:
        c = comp_of((m.group(1) or m.group(2) or "").strip("_"))
        if c is not None:
            return "sigma", c
    return None, None


def _csv_rows(path, lines: list[str]):
    """(header_line_no, header_fields, [(line_no, fields)], comment_lines) of a delimited file."""
    comments, body = [], []
    for i, ln in enumerate(lines, start=1):
        if not ln.strip():
            continue
        if ln.lstrip().startswith("#") and not body:
            comments.append((i, ln))
            continue
        body.append((i, ln))
    if not body:
        raise _error(path, None, "no header row and no data")
    hi, hline = body[0]
    delim = next((d for d in (",", ";", "\t") if d in hline), None)

    def split(ln):
        if delim is None:
            return ln.split()
        return [f.strip() for f in next(csv.reader([ln], delimiter=delim, skipinitialspace=True))]

    rows = [(i, split(ln)) for i, ln in body[1:]]
    return hi, split(hline), rows, comments, delim


def read_measurement_csv(
    path, *, angle_deg: Optional[float] = None, quantity: Optional[str] = None
) -> Measurement:
    """Read a measurement from a delimited text file (plain CSV, or one written by :func:`write_measurement_csv`).

    Columns are found by their header (any order, case-insensitive, quoted or not):

    * wavelength: ``wavelength``/``lambda``/``wl`` with a unit in the name — ``wavelength (nm)``,
      ``wavelength_um``, ``Wavelength [µm]``, ``lambda (Å)`` —, or ``energy (eV)``, ``wavenumber (1/cm)``,
      or a bare unit (``nm``, ``eV``). **A wavelength without unit is refused.**
    * angle (optional): ``angle``, ``aoi``, ``angle of incidence``, ``theta`` (degrees; ``(rad)`` converted);
      without one, pass ``angle_deg=``.
    * values: ``psi`` and ``delta`` (or ψ, Δ; degrees), ``M11`` … ``M44`` (``mm12`` too), ``R`` /
      ``reflectance``, ``T`` / ``transmittance`` — with ``%`` in the name (``%R``, ``R (%)``,
      ``T_percent``) for percent; σ columns: ``sigma_psi``, ``psi_err``, ``psi error`` ….
    * other columns are ignored (listed in ``metadata["ignored_columns"]``).

    Args:
        path: the file; ``#`` lines before the header are comments (``# key = value`` lines of a
            measurement CSV restore the metadata).
        angle_deg: angle of incidence, degrees, when the file has no angle column.
        quantity: which quantity to take when the file holds several (e.g. both R and T).

    Returns:
        :class:`Measurement` (fractions for R/T, nm, degrees).

    Raises:
        LayerstackError: naming the file, line and column: no wavelength column or no unit for it,
        values in % without ``%`` in the header (values above 1.5 in an R/T column), a
        non-number, a row with the wrong number of fields, several quantities without ``quantity=``.
    """
    lines = _read_text(path)
    hi, header, rows, comments, delim = _csv_rows(path, lines)
    meta_pairs: list[tuple[str, str]] = []
    is_ours = bool(comments) and comments[0][1].strip() == _MAGIC
    extras: dict[str, list[list[float]]] = {}
    if is_ours:
        for i, ln in comments[1:]:
            body = ln.lstrip()[1:].strip()
            if body.startswith("extra "):
                parts = body.split()
                nums = _numbers(parts[2:])
                if nums is None or len(nums) != 4:
                    raise _error(path, i, "an 'extra' line needs a label and 4 numbers")
                extras.setdefault(parts[1], []).append(nums)
            elif "=" in body:
                k, v = body.split("=", 1)
                try:
                    meta_pairs.append((k.strip(), json.loads(v)))
                except json.JSONDecodeError:
                    raise _error(path, i, f"the value of {k.strip()!r} is not a JSON string") from None
    roles = []
    for raw in header:
        name, unit = _split_header_name(raw)
        role, comp = _column_role(name, unit)
        roles.append((role, comp, unit, raw))
    wl_cols = [k for k, r in enumerate(roles) if r[0] == "wavelength"]
    if not wl_cols:
        raise _error(path, hi, f"no wavelength column in the header ({', '.join(header)}); name it e.g. 'wavelength (nm)'")
    wl_col = wl_cols[0]
    wl_name, wl_unit = _split_header_name(header[wl_col])
    unit = wl_unit or (wl_name if _unit(wl_name) else "")
    if _unit(unit) is None:
        raise _error(
            path, hi,
            f"column {header[wl_col]!r}: no wavelength unit; name it 'wavelength (nm)', 'wavelength_um', "
            "'energy (eV)' or 'wavenumber (1/cm)'",
        )
    comps_present = {r[1] for r in roles if r[0] == "value"}
    candidates = []
    if {"psi", "delta"} <= comps_present:
        candidates.append("psi_delta")
    if any(c.startswith("M") for c in comps_present):
        candidates.append("mueller")
    if "R" in comps_present:
        candidates.append("reflectance")
    if "T" in comps_present:
        candidates.append("transmittance")
    saved = dict(meta_pairs)  # the measurement CSV's own keys
    if quantity is None and "quantity" in saved:
        quantity = saved["quantity"]
    if quantity is not None:
        if quantity not in QUANTITIES:
            raise LayerstackError(f"quantity must be one of {QUANTITIES}, got {quantity!r}")
        if quantity not in candidates:
            raise _error(path, hi, f"no columns for quantity {quantity!r} in the header ({', '.join(header)})")
    elif not candidates:
        raise _error(path, hi, f"no measured columns (psi & delta, M11…M44, R or T) in the header ({', '.join(header)})")
    elif len(candidates) > 1:
        raise _error(path, hi, f"the file holds {', '.join(candidates)}: pass quantity= to choose one")
    else:
        quantity = candidates[0]
    names = component_names(quantity)
    value_col = {r[1]: k for k, r in enumerate(roles) if r[0] == "value" and r[1] in names}
    sigma_col = {r[1]: k for k, r in enumerate(roles) if r[0] == "sigma" and r[1] in names}
    missing = [n for n in names if n not in value_col and not (n == "M11")]
    if missing:
        raise _error(path, hi, f"quantity {quantity!r} needs columns {', '.join(missing)}")
    ang_col = next((k for k, r in enumerate(roles) if r[0] == "angle"), None)
    if ang_col is None and angle_deg is None:
        raise _error(path, hi, "no angle-of-incidence column: pass angle_deg= (e.g. 0 for normal incidence)")
    used = {wl_col, ang_col, *value_col.values(), *sigma_col.values()}
    ignored = [header[k] for k in range(len(header)) if k not in used]

    data = np.empty((len(rows), len(header)))
    for r, (i, fields) in enumerate(rows):
        if len(fields) != len(header):
            raise _error(
                path, i,
                f"{len(fields)} fields, the header has {len(header)}" + (" (truncated file?)" if i == len(lines) else ""),
            )
        for k, t in enumerate(fields):
            v = _float(t)
            if v is None and delim == ";" and "," in t:
                v = _float(t.replace(",", "."))
            if v is None:
                raise _error(path, i, f"column {header[k]!r}: {t!r} is not a number")
            data[r, k] = v
    if data.shape[0] == 0:
        raise _error(path, len(lines), "a header but no data rows")

    def line_of(row):
        return rows[row][0]

    wl = wavelength_to_nm(data[:, wl_col], unit)
    if not np.all(np.isfinite(wl) & (wl > 0)):
        r = int(np.argmax(~(np.isfinite(wl) & (wl > 0))))
        raise _error(path, line_of(r), f"wavelength {data[r, wl_col]!r} {unit} is not a positive number")
    if ang_col is not None:
        ang_unit = roles[ang_col][2].lower()
        ang = np.rad2deg(data[:, ang_col]) if ang_unit.startswith("rad") else data[:, ang_col]
    else:
        ang = np.full(data.shape[0], float(angle_deg))
    bad = np.flatnonzero(~((ang >= 0) & (ang < 90)))
    if bad.size:
        _check_angle(path, line_of(int(bad[0])) if ang_col is not None else None, float(ang[bad[0]]))

    comps, sig = {}, {}
    for n in names:
        if n not in value_col:  # M11 of a normalised Mueller table
            comps[n] = np.ones(data.shape[0])
            sig[n] = np.zeros(data.shape[0]) if sigma_col else None
            continue
        k = value_col[n]
        v = data[:, k].copy()
        s = data[:, sigma_col[n]].copy() if n in sigma_col else None
        if quantity in ("reflectance", "transmittance"):
            if roles[k][2] == "%":
                v /= 100.0
                if s is not None:
                    s /= 100.0
            elif np.nanmax(v) > 1.5:
                r = int(np.nanargmax(v))
                raise _error(
                    path, line_of(r),
                    f"column {header[k]!r} = {v[r]:g}: a fraction cannot exceed 1; "
                    f"if the file is in percent, say so in the header (e.g. '{header[k]} (%)' or '%{header[k]}')",
                )
        if quantity == "psi_delta" and n == "psi":
            bad = np.flatnonzero(~(np.isnan(v) | ((v >= 0) & (v <= 90))))
            if bad.size:
                raise _error(path, line_of(int(bad[0])), f"psi = {float(v[bad[0]])!r} is not in [0, 90] degrees")
        comps[n], sig[n] = v, s
    sigma = sig if all(sig.get(n) is not None for n in names) else None

    fields = dict(file_format="csv", source=str(path), delta_convention="instrument")
    meta = [("wavelength_unit", unit)]
    if ignored:
        meta.append(("ignored_columns", ", ".join(ignored)))
    if ang_col is None:
        meta.append(("angle_source", "given by the caller"))
    normalized = quantity == "mueller" and "M11" not in value_col
    if is_ours:
        fields = dict(
            file_format=saved.get("file_format", "csv"),
            source=saved.get("source", str(path)),
            delta_convention=saved.get("delta_convention", "instrument"),
        )
        normalized = saved.get("mueller_normalized", "false") == "true"
        meta = [(k[5:], v) for k, v in meta_pairs if k.startswith("meta.")]
    return _warn_implausible(path, measurement_from_points(
        quantity, ang, wl, comps, sigma=sigma, extras=extras, where=str(path),
        mueller_normalized=normalized, metadata=tuple(meta), **fields,
    ))


def write_measurement_csv(path, measurement: Measurement) -> Path:
    """Write a :class:`Measurement` as a measurement CSV (read back identically by :func:`read_measurement_csv`).

    Format (comma-separated, numbers as Python ``repr`` so every float survives exactly)::

        # layerstack measurement csv v1
        # quantity = "psi_delta"
        # delta_convention = "instrument"
        # file_format = "woollam"
        # source = "path/of/the/original.dat"
        # mueller_normalized = "false"
        # meta.<key> = "<value>"           (one line per metadata pair, in order; JSON strings)
        # extra <label> <wavelength_nm> <second column> <value> <sigma>   (one line per extra row)
        angle_deg,wavelength_nm,psi,delta,sigma_psi,sigma_delta
        65.0,300.0,12.140821,1.5609661,0.37071,3.46024
        …

    One row per grid point (angle-major, then wavelength), ``nan`` where the file had no value;
    components as in :meth:`Measurement.to_arrays`. Values and text must not contain newlines.

    Returns:
        The path written.
    """
    m = measurement
    path = Path(path)
    arrays = m.to_arrays()
    angles = arrays.pop("angles_deg")
    wls = arrays.pop("wavelength_nm")
    names = list(arrays)
    def text(v) -> str:
        return json.dumps(str(v), ensure_ascii=False)

    out = [_MAGIC]
    for key in ("quantity", "delta_convention", "file_format", "source"):
        out.append(f"# {key} = {text(getattr(m, key))}")
    out.append(f"# mueller_normalized = {text(str(bool(m.mueller_normalized)).lower())}")
    for k, v in m.metadata:
        if "\n" in str(k) or "=" in str(k):
            raise LayerstackError(f"Measurement.metadata key {k!r} cannot be written (newline or '=')")
        out.append(f"# meta.{k} = {text(v)}")
    for label, rows in m.extras.items():
        if not label or any(c.isspace() for c in label):
            raise LayerstackError(f"Measurement.extras label {label!r} must be one word")
        out += [f"# extra {label} " + " ".join(repr(float(x)) for x in row) for row in np.asarray(rows)]
    out.append(",".join(["angle_deg", "wavelength_nm", *names]))
    for ia, a in enumerate(angles):
        for iw, w in enumerate(wls):
            out.append(",".join([repr(float(a)), repr(float(w)), *(repr(float(arrays[n][ia, iw])) for n in names)]))
    path.write_text("\n".join(out) + "\n", encoding="utf-8")
    return path


# ---------------------------------------------------------------------------------------------
# sniffing
# ---------------------------------------------------------------------------------------------
def sniff_format(path) -> str:
    """The format of an instrument file: ``"nexus"``, ``"jcamp"``, ``"sentech"``, ``"accurion"``,
    ``"woollam"`` or ``"csv"`` (from the first bytes and lines, not the extension alone)."""
    path = Path(path)
    if not path.is_file():
        raise LayerstackError(f"{path}: no such file")
    with open(path, "rb") as fh:
        head = fh.read(8192)
    if head.startswith(b"\x89HDF\r\n\x1a\n"):
        return "nexus"
    if path.suffix.lower() in (".nxs", ".h5", ".hdf5", ".nx5"):
        return "nexus"
    text = head.decode("latin-1")
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()][:12]
    if not lines:
        raise LayerstackError(f"{path}: empty file")
    if lines[0].startswith("##"):
        return "jcamp"
    if lines[0].startswith(";") and "wavelength" in lines[0].lower():
        return "sentech"
    if lines[0].startswith("#") and {"lambda", "aoi", "psi", "delta"} <= {t.lower() for t in lines[0].lstrip("#").split()}:
        return "accurion"
    if lines[0] == _MAGIC.strip():
        return "csv"
    for ln in lines[:6]:
        tokens = ln.split()
        if ln.lower().startswith("vasemethod") or _woollam_unit_line(tokens) is not None:
            return "woollam"
    return "csv"


def read_measurement(path, **options) -> Measurement:
    """Read any supported instrument file, choosing the reader from the content (:func:`sniff_format`).

    Args:
        path: the file.
        **options: passed to the reader (``angle_deg``/``percent`` for JCAMP-DX, ``angle_deg``/
            ``quantity`` for CSV, ``entry`` for NeXus); an option the chosen reader does not take
            is an error.

    Returns:
        :class:`Measurement` (module docstring for the conventions).
    """
    fmt = sniff_format(path)
    reader = {
        "nexus": read_nexus,
        "jcamp": read_jcamp,
        "sentech": read_sentech,
        "accurion": read_accurion,
        "woollam": read_woollam,
        "csv": read_measurement_csv,
    }[fmt]
    try:
        return reader(path, **options)
    except TypeError as err:
        if "unexpected keyword" in str(err):
            raise LayerstackError(f"{path}: the {fmt} reader does not take option(s) {sorted(options)}") from None
        raise
