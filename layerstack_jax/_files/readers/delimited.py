"""Plain delimited text (comma, semicolon, tab or blanks; quoted
headers as R and Excel write them) and the measurement CSV written by
:func:`write_measurement_csv` (round trip exact).
"""

from __future__ import annotations

import csv
import json
import re
from pathlib import Path
from typing import Optional

import numpy as np

from ..._base.validate import LayerstackError
from ..measurement import (
    QUANTITIES,
    Measurement,
    component_names,
    measurement_from_points,
)
from .common import (
    Format,
    Head,
    check_angle,
    error,
    is_missing,
    numbers,
    read_text,
    refuse_cut_number,
    to_float,
    unit_of,
    warn_implausible,
    wavelength_to_nm,
)

MAGIC = "# layerstack measurement csv v1"


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

    if name in _WAVELENGTH_NAMES or (not name and unit_of(unit)) or (unit_of(name) is not None and not unit):
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


def names_an_angle(header: list[str]) -> bool:
    """True when a header names an angle-of-incidence column (``angle``, ``AOI (deg)``, ``theta`` …):
    the table is then a measurement (points at angles), not one spectrum per column."""
    return any(_column_role(*_split_header_name(h))[0] == "angle" for h in header)


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
        raise error(path, None, "no header row and no data")
    hi, hline = body[0]
    delim = next((d for d in (",", ";", "\t") if d in hline), None)

    def split(ln):
        if delim is None:
            return ln.split()
        return [f.strip() for f in next(csv.reader([ln], delimiter=delim, skipinitialspace=True))]

    rows = [(i, split(ln)) for i, ln in body[1:]]
    return hi, split(hline), rows, comments, delim


def _number(token: str, *, decimal_comma: bool) -> Optional[float]:
    """The number a cell spells; ``0,5`` too where the columns are not comma-separated."""
    v = to_float(token)
    if v is None and decimal_comma and token.count(",") == 1 and "." not in token:
        v = to_float(token.replace(",", "."))
    return v


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
    lines = read_text(path)
    hi, header, rows, comments, delim = _csv_rows(path, lines)
    meta_pairs: list[tuple[str, str]] = []
    is_ours = bool(comments) and comments[0][1].strip() == MAGIC
    extras: dict[str, list[list[float]]] = {}
    if is_ours:
        for i, ln in comments[1:]:
            body = ln.lstrip()[1:].strip()
            if body.startswith("extra "):
                parts = body.split()
                nums = numbers(parts[2:])
                if nums is None or len(nums) != 4:
                    raise error(path, i, "an 'extra' line needs a label and 4 numbers")
                extras.setdefault(parts[1], []).append(nums)
            elif "=" in body:
                k, v = body.split("=", 1)
                try:
                    meta_pairs.append((k.strip(), json.loads(v)))
                except json.JSONDecodeError:
                    raise error(path, i, f"the value of {k.strip()!r} is not a JSON string") from None
    roles = []
    for raw in header:
        name, unit = _split_header_name(raw)
        role, comp = _column_role(name, unit)
        roles.append((role, comp, unit, raw))
    wl_cols = [k for k, r in enumerate(roles) if r[0] == "wavelength"]
    if not wl_cols:
        raise error(path, hi, f"no wavelength column in the header ({', '.join(header)}); name it e.g. 'wavelength (nm)'")
    wl_col = wl_cols[0]
    wl_name, wl_unit = _split_header_name(header[wl_col])
    unit = wl_unit or (wl_name if unit_of(wl_name) else "")
    if unit_of(unit) is None:
        raise error(
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
            raise error(path, hi, f"no columns for quantity {quantity!r} in the header ({', '.join(header)})")
    elif not candidates:
        raise error(path, hi, f"no measured columns (psi & delta, M11…M44, R or T) in the header ({', '.join(header)})")
    elif len(candidates) > 1:
        raise error(path, hi, f"the file holds {', '.join(candidates)}: pass quantity= to choose one")
    else:
        quantity = candidates[0]
    names = component_names(quantity)
    value_col = {r[1]: k for k, r in enumerate(roles) if r[0] == "value" and r[1] in names}
    sigma_col = {r[1]: k for k, r in enumerate(roles) if r[0] == "sigma" and r[1] in names}
    missing = [n for n in names if n not in value_col and not (n == "M11")]
    if missing:
        raise error(path, hi, f"quantity {quantity!r} needs columns {', '.join(missing)}")
    ang_col = next((k for k, r in enumerate(roles) if r[0] == "angle"), None)
    if ang_col is None and angle_deg is None:
        raise error(path, hi, "no angle-of-incidence column: pass angle_deg= (e.g. 0 for normal incidence)")
    used = {wl_col, ang_col, *value_col.values(), *sigma_col.values()}
    ignored = [header[k] for k in range(len(header)) if k not in used]

    data = np.full((len(rows), len(header)), np.nan)
    required = {wl_col, ang_col} - {None}
    for r, (i, fields) in enumerate(rows):
        if len(fields) != len(header):
            hint = " (truncated file?)" if i == len(lines) and len(fields) < len(header) else ""
            if delim == "," and len(fields) > len(header) and re.search(r"\d,\d", ",".join(fields)):
                hint += " (decimal commas? they need ';' or tabs between the columns)"
            raise error(path, i, f"{len(fields)} fields, the header has {len(header)}{hint}")
        for k in sorted(used - {None}):
            t = fields[k]
            v = _number(t, decimal_comma=delim != ",")
            if is_missing(t):
                if k in required:
                    raise error(path, i, f"column {header[k]!r} (column {k + 1}): no value ({t!r}); every row needs its "
                                         f"{roles[k][0]}")
                v = np.nan  # a missing point: NaN, masked per point (Measurement.valid)
            if v is None:
                raise error(path, i, f"column {header[k]!r}: {t!r} is not a number (column {k + 1})")
            data[r, k] = v
    if data.shape[0] == 0:
        raise error(path, len(lines), "a header but no data rows")
    refuse_cut_number(path, lines, rows[-1][0], rows[-1][1], [f for _, f in rows[:-1]], header)

    def line_of(row):
        return rows[row][0]

    wl = wavelength_to_nm(data[:, wl_col], unit)
    if not np.all(np.isfinite(wl) & (wl > 0)):
        r = int(np.argmax(~(np.isfinite(wl) & (wl > 0))))
        raise error(path, line_of(r), f"wavelength {data[r, wl_col]!r} {unit} is not a positive number "
                                         f"(column {wl_col + 1}, {header[wl_col]!r})")
    if ang_col is not None:
        ang_unit = roles[ang_col][2].lower()
        ang = np.rad2deg(data[:, ang_col]) if ang_unit.startswith("rad") else data[:, ang_col]
    else:
        ang = np.full(data.shape[0], float(angle_deg))
    bad = np.flatnonzero(~((ang >= 0) & (ang < 90)))
    if bad.size:
        check_angle(path, line_of(int(bad[0])) if ang_col is not None else None, float(ang[bad[0]]))

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
            elif np.any(np.isfinite(v)) and np.nanmax(v) > 1.5:
                r = int(np.nanargmax(v))
                raise error(
                    path, line_of(r),
                    f"column {header[k]!r} = {v[r]:g}: a fraction cannot exceed 1; "
                    f"if the file is in percent, say so in the header (e.g. '{header[k]} (%)' or '%{header[k]}')",
                )
        if quantity == "psi_delta" and n == "psi":
            bad = np.flatnonzero(~(np.isnan(v) | ((v >= 0) & (v <= 90))))
            if bad.size:
                raise error(path, line_of(int(bad[0])), f"psi = {float(v[bad[0]])!r} is not in [0, 90] degrees "
                                                             f"(column {k + 1}, {header[k]!r})")
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
    return warn_implausible(path, measurement_from_points(
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

    out = [MAGIC]
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



def _sniff(head: Head) -> bool:
    """Only the measurement CSV's first line: plain CSV is the fallback of sniffing."""
    return bool(head.lines) and head.lines[0] == MAGIC.strip()


FORMAT = Format("csv", read_measurement_csv, _sniff)
