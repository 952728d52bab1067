"""Sentech SpectraRay ASCII exports: a first line
``; WAVELENGTH a1 a1 a2 a2 …`` (the angle of every column), then rows ``wavelength(nm)`` followed
by ψ, Δ pairs per angle, or by the 16 elements M11 … M44 (row-major) of the normalised Mueller
matrix per angle.
"""

from __future__ import annotations

import numpy as np

from ..measurement import Measurement, component_names, measurement_from_points
from .common import (
    Format,
    Head,
    check_angle,
    error,
    read_text,
    refuse_cut_number,
    to_float,
    warn_implausible,
)


def _sentech_numbers(path, i, tokens: list[str]) -> list[float]:
    out = []
    for k, t in enumerate(tokens):
        v = to_float(t)
        if v is None and "," in t and "." not in t:  # decimal comma (German locale exports)
            v = to_float(t.replace(",", "."))
        if v is None:
            raise error(path, i, f"{t!r} is not a number (column {k + 1})")
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
    lines = read_text(path)
    if not lines or not lines[0].lstrip().startswith(";"):
        raise error(path, 1, "not a SpectraRay export: the first line must be '; WAVELENGTH <angle per column> …'")
    head = lines[0].lstrip()[1:].split()
    if not head or head[0].lower() != "wavelength":
        got = head[0] if head else "nothing"
        raise error(path, 1, f"first column is {got!r}; only wavelength (nm) exports are supported")
    angles = _sentech_numbers(path, 1, head[1:])
    n = len(angles)
    if n == 0:
        raise error(path, 1, "the header names no angle columns")
    for a in angles:
        check_angle(path, 1, a)
    rows, row_lines, fields = [], [], []
    for i, line in enumerate(lines[1:], start=2):
        tokens = line.split()
        if not tokens:
            continue
        nums = _sentech_numbers(path, i, tokens)
        if len(nums) != n + 1:
            raise error(
                path,
                i,
                f"expected {n + 1} numbers (wavelength and the {n} columns of the header), got {len(nums)}"
                + (" (truncated file?)" if i == len(lines) else ""),
            )
        rows.append(nums)
        row_lines.append(i)
        fields.append(tokens)
    if not rows:
        raise error(path, len(lines), "no data rows")
    refuse_cut_number(path, lines, row_lines[-1], fields[-1], fields[:-1])
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
        return warn_implausible(path, measurement_from_points(
            "mueller", np.repeat(angs, wl.size), np.tile(wl, angs.size), comps,
            where=str(path), mueller_normalized=True, **fields,
        ))
    if n % 2 or np.any(ang_cols[0::2] != ang_cols[1::2]):
        raise error(path, 1, "psi/delta exports need the angles in pairs (psi, delta) per angle; got " + " ".join(head[1:]))
    angs = ang_cols[0::2]
    psi, delta = vals[:, 0::2], vals[:, 1::2]
    bad = np.argwhere(~((psi >= 0) & (psi <= 90)))
    if bad.size:
        r, c = bad[0]
        raise error(path, row_lines[r], f"psi = {float(psi[r, c])!r} is not in [0, 90] degrees")
    return measurement_from_points(
        "psi_delta", np.repeat(angs, wl.size), np.tile(wl, angs.size),
        {"psi": psi.T.ravel(), "delta": delta.T.ravel()}, where=str(path), **fields,
    )



def _sniff(head: Head) -> bool:
    return bool(head.lines) and head.lines[0].startswith(";") and "wavelength" in head.lines[0].lower()


FORMAT = Format("sentech", read_sentech, _sniff)
