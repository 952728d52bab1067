"""J.A. Woollam WVASE / CompleteEASE ASCII exports (``.dat``): a title
line, optional ``VASEmethod[...]``/``Original[...]`` lines, a wavelength-unit line (``nm``,
``Angstroms``, ``eV``, ``um``), then rows ``wavelength angle psi delta [sigma_psi sigma_delta]``
(WVASE) or the same prefixed by ``E`` (CompleteEASE); rows labelled ``dPolE`` (depolarization, %),
``uR`` … are kept in ``Measurement.extras``; rows ``mm12 wavelength angle value sigma`` (``mmij``,
i, j = 1..4) make a Mueller-matrix measurement normalised by M11 (this row layout follows
CompleteEASE's labelled-row convention; no real Mueller export was at hand to test it).
Time-resolved ("Dynamic") and tan ψ / cos Δ ("TRIG") exports are refused.
"""

from __future__ import annotations

import re
from typing import Optional

import numpy as np

from ..measurement import Measurement, component_names, measurement_from_points
from .common import (
    Format,
    Head,
    check_angle,
    check_range,
    error,
    numbers,
    read_text,
    refuse_cut_number,
    refuse_short_last_block,
    to_float,
    unit_of,
    wavelength_to_nm,
)

_MUELLER_LABEL = re.compile(r"^m{1,2}([1-4])([1-4])$", re.IGNORECASE)
_PSI_DELTA_LABELS = {"e"}
_HEADER_COLUMN_WORDS = {"aoi", "psi", "delta", "angle", "ψ", "δ"}


def woollam_unit_line(tokens: list[str]) -> Optional[str]:
    """The unit of a Woollam unit line (``nm``, ``Angstroms``, ``eV``; refellips-style
    ``nm  AOI  Psi  Delta`` too), or None when the line is not one."""
    if not tokens or unit_of(tokens[0]) is None or unit_of(tokens[0]) == "1/cm":
        return None
    rest = {t.lower() for t in tokens[1:]}
    if rest <= _HEADER_COLUMN_WORDS or "trig" in rest:
        return unit_of(tokens[0])
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
    lines = read_text(path)
    header: list[tuple[int, str]] = []
    unit = None
    start = None
    for i, line in enumerate(lines, start=1):
        tokens = line.split()
        if not tokens:
            continue
        numeric_row = len(tokens) >= 2 and numbers(tokens) is not None
        labelled_row = len(tokens) >= 3 and tokens[0][:1].isalpha() and numbers(tokens[1:]) is not None
        if unit is not None and (numeric_row or labelled_row):
            start = i
            break
        if {t.lower() for t in tokens} & {"trig"}:
            raise error(path, i, "tan(psi)/cos(delta) ('TRIG') exports are not supported; export psi/delta instead")
        if tokens[0].lower() == "dynamic":
            raise error(path, i, "time-resolved ('Dynamic') exports are not supported; export one time slice")
        u = woollam_unit_line(tokens)
        if u is not None:
            unit = u
        header.append((i, line.strip()))
    if unit is None:
        raise error(
            path, None, "no wavelength-unit line ('nm', 'Angstroms', 'eV' or 'um') before the data: not a Woollam export"
        )
    if start is None:
        raise error(path, len(lines), "no data rows after the header")

    pd_rows: list[tuple[int, list[float]]] = []
    mm_rows: dict[str, list[tuple[int, list[float]]]] = {}
    extras: dict[str, list[list[float]]] = {}
    extra_rows: dict[str, list[tuple[int, list[float]]]] = {}
    rows_of_kind: dict[tuple, list[list[str]]] = {}  # the fields of every row, by label and length
    last = None
    for i in range(start, len(lines) + 1):
        tokens = lines[i - 1].split()
        if not tokens:
            continue
        kind = rows_of_kind.setdefault((tokens[0].lower() if to_float(tokens[0]) is None else None, len(tokens)), [])
        kind.append(tokens)
        last = (i, tokens, kind)
        label = None
        if to_float(tokens[0]) is None:
            label, tokens = tokens[0], tokens[1:]
        nums = numbers(tokens)
        if nums is None:
            k, bad = next((k, t) for k, t in enumerate(tokens) if to_float(t) is None)
            raise error(path, i, f"{bad!r} is not a number (column {k + 1 + (label is not None)})")
        if label is None or label.lower() in _PSI_DELTA_LABELS:
            if len(nums) not in (4, 6):
                raise error(
                    path,
                    i,
                    f"expected 4 or 6 numbers (wavelength, angle, psi, delta[, sigma_psi, sigma_delta]), got {len(nums)}"
                    + (" (truncated file?)" if i == len(lines) else ""),
                )
            check_angle(path, i, nums[1])
            check_range(path, i, "psi", nums[2], 0.0, 90.0)
            check_range(path, i, "delta", nums[3], -360.0, 360.0)
            pd_rows.append((i, nums))
        else:
            if len(nums) != 4:
                raise error(
                    path,
                    i,
                    f"a {label!r} row needs 4 numbers (wavelength, angle, value, sigma), got {len(nums)}"
                    + (" (truncated file?)" if i == len(lines) else ""),
                )
            m = _MUELLER_LABEL.match(label)
            if m:
                check_angle(path, i, nums[1])
                check_range(path, i, label, nums[2], -1.5, 1.5, unit="(normalised Mueller element)")
                mm_rows.setdefault(f"M{m.group(1)}{m.group(2)}", []).append((i, nums))
            else:
                label = "dPolE" if label.lower() == "dpole" else label
                extras.setdefault(label, []).append(nums)
                extra_rows.setdefault(label, []).append((i, nums))
    if pd_rows and any(len(r) != len(pd_rows[0][1]) for _, r in pd_rows):
        i = next(i for i, r in pd_rows if len(r) != len(pd_rows[0][1]))
        raise error(path, i, "rows mix 4 and 6 numbers (with and without sigma)")
    if last is not None:
        refuse_cut_number(path, lines, last[0], last[1], last[2][:-1])
    blocks = [("angle", pd_rows)] if pd_rows else []
    blocks += [("angle", rows) for rows in mm_rows.values()]
    blocks += [(f"{label!r} rows' second column", rows) for label, rows in extra_rows.items()]
    for name, rows in blocks:  # every kind of row on (wavelength, angle): the last block must be whole
        a = np.array([r[:2] for _, r in rows])
        wl = wavelength_to_nm(a[:, 0], unit)
        refuse_short_last_block(path, a[:, 1], wl, rows[-1][0], outer_name=name, outer_unit="deg" if name == "angle" else "")
        refuse_short_last_block(path, wl, a[:, 1], rows[-1][0], outer_name="wavelength", outer_unit="nm",
                                inner_name=name, inner_unit="deg" if name == "angle" else "")

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
    raise error(path, len(lines), "no psi/delta ('E') or Mueller ('mmij') rows")


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
                raise error(path, None, f"Mueller export without {name.lower().replace('m', 'mm', 1)} rows")
            comps[name], sig[name] = np.ones_like(ang), np.zeros_like(ang)
            continue
        r = np.array([x for _, x in rows])
        if r.shape[0] != ang.size or not (np.array_equal(r[:, 1], ang) and np.array_equal(r[:, 0], wl)):
            raise error(path, rows[0][0], f"{name} rows are not on the wavelengths and angles of the other elements")
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



def _sniff(head: Head) -> bool:
    return any(ln.lower().startswith("vasemethod") or woollam_unit_line(ln.split()) is not None for ln in head.lines[:6])


FORMAT = Format("woollam", read_woollam, _sniff)
