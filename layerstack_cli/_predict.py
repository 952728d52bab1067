"""``layerstack predict STACK.toml -g GEOM ... -o out.csv [--plot out.png]``."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from layerstack_jax import DEFAULT_NODES, LayerstackError, check_stack, ellipsometry, reflectance
from layerstack_jax.io import load_stack, parse_wavelengths, save_spectra_csv

from ._common import PROG, _describe, _parse_geometries, _plot, _positive_int, _precision

def _add_predict_parser(sub) -> None:
    p = sub.add_parser(
        "predict",
        help="compute spectra of a stack for measurement geometries",
        description="Compute what instruments of the given geometries read for the stack, write a CSV "
        "(wavelength_nm, then one column per geometry) and optionally a PNG plot.",
        epilog="geometries: sphere:ANGLE:sce | sphere:ANGLE:sci (integrating sphere, specular excluded / "
        "included), I/V such as 45/0 or 0/45 (reflectance factor), brdf:I:V (1/sr), specular:ANGLE "
        "(columns R_ANGLE, T_ANGLE, A_ANGLE; or specular:ANGLE:R|T|A for one). Angles in degrees.",
    )
    p.add_argument("stack", metavar="STACK.toml", help="stack file (format: see layerstack_jax.io)")
    p.add_argument("--wavelengths", "-w", default="380:780:5", metavar="GRID",
                   help="start:stop:step in nm (stop included), one value, or a comma list (default 380:780:5)")
    p.add_argument("--geometry", "-g", action="append", required=True, metavar="GEOM",
                   help="measurement geometry; repeat for several (see below)")
    p.add_argument("--output", "-o", required=True, metavar="OUT.csv", help="CSV file to write")
    p.add_argument("--plot", metavar="OUT.png", help="also write a plot of the spectra (PNG)")
    p.add_argument("--float32", action="store_true", help="compute in float32 (default: float64)")
    p.add_argument("--nodes", type=_positive_int, default=DEFAULT_NODES, metavar="N",
                   help=f"Gauss-Legendre nodes per angular segment for diffuse integrals (default {DEFAULT_NODES})")
    p.add_argument("--polarization", choices=("ss", "sp", "ps", "pp", "mueller"), metavar="AB",
                   help="for the brdf:I:V geometries (others stay natural light): the polarization-resolved diffuse BRDF f_AB (A the "
                   "illumination, B the analyser, s or p), or 'mueller' for its 16 Mueller elements "
                   "(columns GEOM_mIJ)")
    p.add_argument("--ellipsometry", action="append", type=float, metavar="ANGLE",
                   help="also write psi_ANGLE and delta_ANGLE (degrees; Delta as instruments report it, 180 - tmm's Delta, in (-180, 180]) "
                   "of a coherent stack; repeat for several angles")
    p.set_defaults(func=_cmd_predict)


def _cmd_predict(args) -> int:
    start = time.perf_counter()
    wavelength = parse_wavelengths(args.wavelengths)
    requested = _parse_geometries(args.geometry)
    with _precision(args.float32):
        stack = load_stack(args.stack)
        try:
            check_stack(stack, wavelength)  # tables cover the grid? (checked once, before any geometry)
        except LayerstackError as e:
            raise LayerstackError(f"{args.stack}: {e}") from None
        if args.polarization and not any(g.supports_polarization for _, g in requested):
            raise LayerstackError("--polarization needs at least one brdf:I:V geometry")
        columns, geometries = {}, {}
        for name, geometry in requested:
            try:
                # Eager (not jitted) on purpose: concrete inputs keep the library's checks,
                # e.g. a wavelength outside a table's range is an error instead of a clamp.
                values = reflectance(stack, wavelength, geometry, nodes=args.nodes)
            except LayerstackError as e:
                raise LayerstackError(f"geometry {name!r}: {e}") from None
            if args.polarization and geometry.supports_polarization:
                try:
                    extra = geometry.polarized_columns(stack, wavelength, name, args.polarization, args.nodes)
                except LayerstackError as e:
                    raise LayerstackError(f"--polarization: {e}") from None
                columns.update(extra)
                geometries.update({k: geometry for k in extra})
                continue
            columns[name] = np.asarray(values, dtype=float)
            geometries[name] = geometry
        for angle in args.ellipsometry or ():
            try:
                e = ellipsometry(stack, wavelength, angle)
            except LayerstackError as err:
                raise LayerstackError(f"--ellipsometry {angle:g}: {err}") from None
            for key, values in ((f"psi_{angle:g}", e.psi_deg), (f"delta_{angle:g}", e.delta_deg)):
                columns[key] = np.asarray(values, dtype=float)
                geometries[key] = None
    bad = [name for name, v in columns.items() if not np.all(np.isfinite(v))]
    if bad:
        print(f"{PROG}: warning: non-finite values in column(s) {', '.join(bad)}", file=sys.stderr)
    out = save_spectra_csv(args.output, wavelength, columns)
    ranges = ", ".join(f"{name} {np.nanmin(v):.4g}..{np.nanmax(v):.4g}" for name, v in columns.items())
    grid = f"{wavelength[0]:g}-{wavelength[-1]:g} nm" if wavelength.size > 1 else f"{wavelength[0]:g} nm"
    elapsed = time.perf_counter() - start
    print(f"{PROG}: wrote {out} ({wavelength.size} wavelengths {grid}; {ranges}) in {elapsed:.1f} s")
    if args.plot:
        plot = Path(args.plot)
        plot.parent.mkdir(parents=True, exist_ok=True)
        _plot(plot, wavelength, columns, geometries, title=Path(args.stack).name, subtitle=_describe(stack))
        print(f"{PROG}: wrote {plot} (plot of {len(columns)} spectr{'um' if len(columns) == 1 else 'a'})")
    return 0


