"""Accurion EP3/EP4 nulling-ellipsometer exports (``#Lambda … AOI Delta
Psi`` header, a ``#nm … deg`` units line); the nulling zones 1–4 of one point are averaged
(as refellips does), no σ.
"""

from __future__ import annotations

import math

import numpy as np

from ..measurement import Measurement, measurement_from_points
from .common import (
    Format,
    Head,
    check_angle,
    check_range,
    error,
    read_text,
    refuse_cut_number,
    refuse_short_last_block,
    to_float,
    unit_of,
    wavelength_to_nm,
)


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
    lines = read_text(path)
    comments = [(i, ln) for i, ln in enumerate(lines, start=1) if ln.startswith("#")]
    if len(comments) < 2:
        raise error(path, 1, "not an Accurion export: expected a '#' header line and a '#' units line")
    (hi, hline), (ui, uline) = comments[0], comments[1]
    names = [t.strip().lower() for t in hline.lstrip("#").split("\t")]
    units = [t.strip() for t in uline.lstrip("#").split("\t")]
    col = {name: k for k, name in enumerate(names)}
    for need in ("lambda", "aoi", "delta", "psi"):
        if need not in col:
            raise error(path, hi, f"no {need!r} column in the header ({', '.join(names)})")
    lam_unit = units[col["lambda"]] if col["lambda"] < len(units) else ""
    if unit_of(lam_unit) is None:
        raise error(path, ui, f"wavelength unit {lam_unit!r} not understood")
    for need in ("aoi", "delta", "psi"):
        u = units[col[need]] if col[need] < len(units) else ""
        if u.lower() not in ("deg", "degree", "degrees", "°"):
            raise error(path, ui, f"column {need!r} is in {u!r}; degrees expected")
    roi = col.get("roiidx")
    zone = col.get("zone")
    rows, fields = [], []
    for i, line in enumerate(lines, start=1):
        if line.startswith("#") or not line.strip():
            continue
        tokens = line.split("\t")
        if len(tokens) < len(names):
            why = f"expected {len(names)} tab-separated fields, got {len(tokens)}"
            raise error(path, i, why + (" (truncated file?)" if i == len(lines) else ""))
        wanted = [col[k] for k in ("lambda", "aoi", "psi", "delta")] + [k for k in (roi, zone) if k is not None]
        bad = next((k for k in wanted if to_float(tokens[k]) is None), None)
        if bad is not None:
            raise error(path, i, f"column {bad + 1} ({names[bad]!r}): {tokens[bad]!r} is not a number")
        r = [float(tokens[col[k]]) for k in ("lambda", "aoi", "psi", "delta")]
        r.append(float(tokens[roi]) if roi is not None else 0.0)
        r.append(float(tokens[zone]) if zone is not None else 1.0)
        check_angle(path, i, r[1])
        if not (math.isnan(r[2]) and math.isnan(r[3])):  # NaN, NaN: a zone that did not null
            check_range(path, i, "psi", r[2], 0.0, 90.0)
            check_range(path, i, "delta", r[3], -360.0, 360.0)
        rows.append(r)
        fields.append((i, [t.strip() for t in tokens]))
    if not rows:
        raise error(path, len(lines), "no data rows")
    refuse_cut_number(path, lines, fields[-1][0], fields[-1][1], [f for _, f in fields[:-1]], names)
    points = np.array(rows)
    refuse_short_last_block(path, points[:, 1], points[:, 0], fields[-1][0], inner_unit=lam_unit)
    refuse_short_last_block(path, points[:, 0], points[:, 1], fields[-1][0], outer_name="wavelength",
                            outer_unit=lam_unit, inner_name="angle", inner_unit="deg")
    a = np.array(rows)
    if np.unique(a[:, 4]).size > 1:
        raise error(path, None, f"the file holds {np.unique(a[:, 4]).size} regions of interest (ROIidx); export one")
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



def _sniff(head: Head) -> bool:
    first = head.lines[0] if head.lines else ""
    return first.startswith("#") and {"lambda", "aoi", "psi", "delta"} <= {t.lower() for t in first.lstrip("#").split()}


FORMAT = Format("accurion", read_accurion, _sniff)
