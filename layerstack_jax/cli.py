"""Command line: ``layerstack predict STACK.toml --geometry 45/0 -o out.csv [--plot out.png]``,
``layerstack fit STACK.toml DATA.csv -g 45/0 -o result.json [--plot fit.png]`` and
``layerstack design DESIGN.toml -o design.toml [--plot design.png]``.

Runnable as ``layerstack`` (console script) or ``python -m layerstack_jax.cli``. The stack file
format is described in :mod:`layerstack_jax.io`.

Unlike the library, the command line enables float64 (``jax_enable_x64``) unless ``--float32``
is given, and restores the previous setting when it returns (so ``main`` can be called
in-process). ``fit`` exits with status 1 when a fit did not converge (the report says why);
``design`` exits with status 1 when the design misses a target (or the required yield) — it
still writes the best design found, and the report says which target failed; a design that
meets every target exits 0 even if the optimizer hit its step limit. Input problems (bad stack
or design file, CSV table, geometry, wavelength grid, unwritable output) print
``layerstack: error: <message>`` to stderr and give exit status 2.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import time
from pathlib import Path

import numpy as np

from ._geometry import BRDF, Directional, Specular, Sphere, parse_geometry, reflectance
from ._materials import Index, Tabulated
from ._quadrature import DEFAULT_NODES
from ._stack import LambertianBackground, Stack, resolve
from ._validate import LayerstackError
from .io import load_stack, parse_wavelengths, save_spectra_csv

__all__ = ["main"]

PROG = "layerstack"


# ------------------------------------------------------------------- shared helpers
@contextlib.contextmanager
def _precision(float32: bool):
    """float64 unless ``float32``; restores the previous JAX setting afterwards."""
    import jax

    previous = bool(jax.config.read("jax_enable_x64"))
    jax.config.update("jax_enable_x64", not float32)
    try:
        yield
    finally:
        jax.config.update("jax_enable_x64", previous)


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {v}")
    return v


def _parse_geometries(texts: list[str]) -> list[tuple[str, object]]:
    """``[(column name, Geometry)]`` for the requested geometries, validated before any work.

    ``specular:θ`` expands into three columns ``R_θ, T_θ, A_θ``; ``specular:θ:Q`` gives ``Q_θ``.
    Other geometries give one column named after the geometry string.
    """
    columns: list[tuple[str, object]] = []
    for text in texts:
        text = text.strip()
        g = parse_geometry(text)  # raises LayerstackError with the list of accepted forms
        angles = (g.angle_deg,) if isinstance(g, Specular) else (g.incidence_deg,) if isinstance(g, Sphere) else (
            g.incidence_deg,
            g.viewing_deg,
        )
        for a in angles:
            if not 0.0 <= float(a) < 90.0:
                raise LayerstackError(f"geometry {text!r}: angles must lie in [0, 90) degrees, got {float(a):g}")
        if isinstance(g, Specular):
            parts = text.split(":")
            angle = parts[1].strip()
            quantities = ("R", "T", "A") if len(parts) == 2 else (g.quantity,)
            columns += [(f"{q}_{angle}", Specular(g.angle_deg, q)) for q in quantities]
        else:
            columns.append((text, g))
    names = [name for name, _ in columns]
    for name in names:
        if names.count(name) > 1:
            raise LayerstackError(f"geometry {name!r} requested twice")
    return columns


def _describe(stack: Stack) -> str:
    """One-line summary of a stack for plot titles: ``air | SiO2 120 nm | substrate``."""

    def index(m):
        if isinstance(m, Index) and np.ndim(m.n) == 0:
            return f"n={float(np.asarray(m.n)):g}"
        if isinstance(m, Tabulated):
            return m.name.split(" (")[0]
        return type(m).__name__

    parts = [f"ambient {index(stack.ambient)}"]
    for layer in stack.layers:
        d = float(np.asarray(layer.thickness))
        size = f"{d / 1000:g} µm" if d >= 1000 else f"{d:g} nm"
        parts.append(f"{layer.name or 'layer'} {size}{'' if layer.coherent else ' (incoherent)'}")
    if isinstance(stack.exit, LambertianBackground):
        parts.append(f"Lambertian background {index(stack.exit.index)}")
    else:
        parts.append(f"substrate {index(stack.exit.index)}")
    return " | ".join(parts)


def _quantity_label(geometry) -> str:
    if geometry is None:  # --ellipsometry columns
        return "degrees"
    if isinstance(geometry, BRDF):
        return "BRDF (1/sr)"
    if isinstance(geometry, Directional):
        return "reflectance factor"
    if isinstance(geometry, Sphere):
        return "reflectance"
    return {"R": "reflectance", "T": "transmittance", "A": "absorptance"}[geometry.quantity]


def _plot(path: Path, wavelength, columns: dict, geometries: dict, title: str, subtitle: str) -> None:
    """Spectra as a PNG (matplotlib object API with the Agg canvas: no global backend change)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8, 4.8), dpi=120, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    brdf = [name for name in columns if isinstance(geometries[name], BRDF)]
    others = [name for name in columns if name not in brdf]
    ax_brdf = ax if not others else (ax.twinx() if brdf else None)
    styles = {"R": "-", "T": "--", "A": ":"}
    lines = []
    for i, name in enumerate(others + brdf):
        g = geometries[name]
        target = ax_brdf if name in brdf else ax
        style = styles[g.quantity] if isinstance(g, Specular) else "-"
        label = f"{name} ({_quantity_label(g)})" if name in brdf and others else name
        (line,) = target.plot(wavelength, columns[name], style, color=f"C{i}", lw=1.8, label=label)
        lines.append(line)
    kinds = list(dict.fromkeys(_quantity_label(geometries[n]) for n in others))
    ax.set_xlabel("wavelength (nm)")
    ax.set_ylabel(" / ".join(kinds) if others else "BRDF (1/sr)")
    if brdf and others:
        ax_brdf.set_ylabel("BRDF (1/sr)")
        ax_brdf.set_ylim(bottom=0)
    if len(wavelength) > 1:
        ax.set_xlim(float(wavelength[0]), float(wavelength[-1]))
    lo = min(float(np.nanmin(columns[n])) for n in (others or brdf))
    ax.set_ylim(bottom=min(0.0, lo))
    ax.grid(True, alpha=0.3)
    ax.legend(handles=lines, loc="best", frameon=False)
    ax.set_title(f"{title}\n{subtitle}", fontsize=10)
    fig.savefig(path)


# ---------------------------------------------------------------------- predict
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
                   help="also write psi_ANGLE and delta_ANGLE (degrees; Delta in (-180, 180], tmm's + 180) "
                   "of a coherent stack; repeat for several angles")
    p.set_defaults(func=_cmd_predict)


def _polarized_columns(stack, wavelength, name, geometry, polarization, nodes) -> dict:
    """Columns for ``--polarization`` of one brdf:I:V geometry (diffuse part, 1/sr)."""
    from ._polarimetry import diffuse_mueller, polarized_brdf

    if not isinstance(geometry, BRDF):
        raise LayerstackError(f"geometry {name!r}: --polarization applies to brdf:I:V geometries only")
    i, v = geometry.incidence_deg, geometry.viewing_deg
    if polarization == "mueller":
        M = np.asarray(diffuse_mueller(stack, wavelength, i, v, nodes=nodes), dtype=float)
        return {f"{name}_m{a}{b}": M[a, b] for a in range(4) for b in range(4)}
    f = np.asarray(polarized_brdf(stack, wavelength, i, v, nodes=nodes), dtype=float)
    a, b = ("sp".index(c) for c in polarization)
    return {f"{name}_{polarization}": f[a, b]}


def _cmd_predict(args) -> int:
    start = time.perf_counter()
    wavelength = parse_wavelengths(args.wavelengths)
    requested = _parse_geometries(args.geometry)
    with _precision(args.float32):
        stack = load_stack(args.stack)
        try:
            resolve(stack, wavelength)  # tables cover the grid? (checked once, before any geometry)
        except LayerstackError as e:
            raise LayerstackError(f"{args.stack}: {e}") from None
        if args.polarization and not any(isinstance(g, BRDF) for _, g in requested):
            raise LayerstackError("--polarization needs at least one brdf:I:V geometry")
        columns, geometries = {}, {}
        for name, geometry in requested:
            try:
                # Eager (not jitted) on purpose: concrete inputs keep the library's checks,
                # e.g. a wavelength outside a table's range is an error instead of a clamp.
                values = reflectance(stack, wavelength, geometry, nodes=args.nodes)
            except LayerstackError as e:
                raise LayerstackError(f"geometry {name!r}: {e}") from None
            if args.polarization and isinstance(geometry, BRDF):
                try:
                    extra = _polarized_columns(stack, wavelength, name, geometry, args.polarization, args.nodes)
                except LayerstackError as e:
                    raise LayerstackError(f"--polarization: {e}") from None
                columns.update(extra)
                geometries.update({k: geometry for k in extra})
                continue
            columns[name] = np.asarray(values, dtype=float)
            geometries[name] = geometry
        for angle in args.ellipsometry or ():
            from ._ellipsometry import ellipsometry

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


# -------------------------------------------------------------------------- fit
def _add_fit_parser(sub) -> None:
    p = sub.add_parser(
        "fit",
        help="fit the free parameters of a stack to measured spectra",
        description="Fit the parameters declared free in the stack file (e.g. thickness_nm = { value = 30000, "
        "free = true, min = 0, max = 1e5 }) to the spectra of a CSV file (wavelength_nm, then one column per "
        "spectrum). Each spectrum is fitted independently (one compiled solver for all), or all together with "
        "--joint (parameters with per_sample = true get one value per spectrum, the others are shared). Prints "
        "the report(s) and writes the results as JSON.",
    )
    p.add_argument("stack", metavar="STACK.toml", help="stack file with free parameters")
    p.add_argument("data", metavar="DATA.csv", help="measured spectra: wavelength_nm, then one column per spectrum")
    p.add_argument("--geometry", "-g", default="sphere:8:sce", metavar="GEOM",
                   help="measurement geometry of the spectra (default sphere:8:sce; see `layerstack predict -h`)")
    p.add_argument("--output", "-o", required=True, metavar="OUT.json", help="JSON results to write")
    p.add_argument("--plot", metavar="OUT.png", help="also plot data vs fit with residuals (PNG)")
    p.add_argument("--wavelengths", "-w", metavar="GRID",
                   help="model grid (default: the data's wavelengths); data are resampled onto it, never extrapolated")
    p.add_argument("--sigma", type=float, metavar="S",
                   help="standard deviation of every data point (absolute uncertainties); default: scale by reduced chi2")
    p.add_argument("--method", default="lm", choices=("lm", "gauss-newton", "dogleg", "bfgs", "lbfgsb", "trf"),
                   help="solver (default lm; lbfgsb and trf keep bounds exactly; trf: scipy's bounded least squares, for joint fits)")
    p.add_argument("--columns", metavar="A,B,...", help="fit only these spectrum columns (default: all)")
    p.add_argument("--joint", action="store_true", help="fit all spectra together (calibration series)")
    p.add_argument("--background", metavar="COLUMN",
                   help="with --joint: the column measured on the bare background (no layers); fitted together with "
                        "the coated samples, it pins rho_g where they are dark")
    p.add_argument("--starts", type=_positive_int, default=1, metavar="K", help="multi-start with K starting points")
    p.add_argument("--max-steps", type=_positive_int, default=256, metavar="N", help="solver step limit (default 256)")
    p.add_argument("--float32", action="store_true", help="compute in float32 (default: float64)")
    p.add_argument("--nodes", type=_positive_int, default=DEFAULT_NODES, metavar="N",
                   help=f"Gauss-Legendre nodes per angular segment for diffuse integrals (default {DEFAULT_NODES})")
    p.set_defaults(func=_cmd_fit)


def _fit_parameters(declarations: list, source: str) -> list:
    import fitting

    params = []
    for d in declarations:
        params.append(fitting.Parameter(
            tuple(d["path"]), d["kind"], d["name"], None, d["lower"], d["upper"], d["basis"], d["per_sample"],
            d["smoothness"],
        ))
    if not params:
        raise LayerstackError(f"{source}: no free parameter: mark some with e.g. thickness_nm = {{ value = 30000, free = true }}")
    return params


def _cmd_fit(args) -> int:
    import json

    from .io import load_fit_stack, read_spectra_csv

    start = time.perf_counter()
    geometry = parse_geometry(args.geometry)
    data_wl, columns = read_spectra_csv(args.data)
    grid = data_wl if args.wavelengths is None else parse_wavelengths(args.wavelengths)
    with _precision(args.float32):
        import fitting

        stack, declarations = load_fit_stack(args.stack)
        params = _fit_parameters(declarations, args.stack)
        names = list(columns)
        if args.columns:
            wanted = [c.strip() for c in args.columns.split(",") if c.strip()]
            missing = [c for c in wanted if c not in columns]
            if missing or not wanted:
                raise LayerstackError(f"{args.data}: no column(s) {missing or args.columns!r}; columns: {', '.join(names)}")
            names = wanted
        if args.background is not None:
            if not args.joint:
                raise LayerstackError("--background needs --joint (the bare background is fitted with the samples)")
            if args.background not in columns:
                raise LayerstackError(f"{args.data}: no column {args.background!r} (--background); columns: {', '.join(names)}")
            names = [n for n in names if n != args.background]
        Y = np.stack([columns[n] for n in names])
        own_grid = None if args.wavelengths is None else data_wl

        def objective(rows):
            ds = [fitting.Dataset(geometry, rows, sigma=args.sigma, wavelength_nm=own_grid, name=Path(args.data).name)]
            if args.background is not None:
                ds.append(fitting.Dataset(geometry, columns[args.background], sigma=args.sigma, wavelength_nm=own_grid,
                                          name=f"{args.background} (bare background)", bare=True))
            try:
                return fitting.Objective(stack, grid, ds, params, n_samples=rows.shape[0], nodes=args.nodes)
            except LayerstackError as e:
                raise LayerstackError(f"{args.data}: {e}") from None

        results = []
        if args.joint:
            obj = objective(Y)
            results.append(("+".join(names), fitting.fit(obj, args.method, starts=args.starts, max_steps=args.max_steps)))
        else:
            if any(p.per_sample for p in params):
                raise LayerstackError(f"{args.stack}: per_sample parameters need --joint")
            obj = objective(Y[:1])
            rows = Y if own_grid is None else fitting.resample(own_grid, Y, grid, what=args.data)
            if args.starts == 1 and args.method not in fitting.HOST_METHODS:
                # all columns in one compiled, vmapped solve
                batch = fitting.fit_batch(obj, rows, args.method, max_steps=args.max_steps, full_results=True)
                results.extend(zip(names, batch.results))
            else:  # multi-start or a host solver: one fit per column, one compiled solver for all
                results.extend((name, fitting.fit(obj, args.method, data=[y[None]], starts=args.starts,
                                                  max_steps=args.max_steps)) for name, y in zip(names, rows))
    for name, r in results:
        print(f"\n### {name}\n{r.report()}")
    out = Path(args.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    payload = {
        "stack": str(args.stack),
        "data": str(args.data),
        "geometry": args.geometry,
        "joint": bool(args.joint),
        "background": args.background,
        "fits": [{"spectrum": name, **r.to_dict()} for name, r in results],
    }
    out.write_text(json.dumps(payload, indent=1))
    n_ok = sum(r.converged for _, r in results)
    print(f"{PROG}: wrote {out} ({len(results)} fit(s), {n_ok} converged) in {time.perf_counter() - start:.1f} s")
    if args.plot:
        plot = Path(args.plot)
        results[0][1].plot(plot, title=Path(args.stack).name)
        print(f"{PROG}: wrote {plot} (data vs fit{' of ' + results[0][0] if len(results) > 1 else ''})")
    return 0 if n_ok == len(results) else 1


# ----------------------------------------------------------------------- design
def _add_design_parser(sub) -> None:
    p = sub.add_parser(
        "design",
        help="optimise layer thicknesses of a stack towards spectral and colour targets",
        description="Optimise the layer thicknesses marked free in a design file (a stack file with "
        "thickness_nm = { value = 100, free = true, min = 0, max = 400 }, [[targets]], [optimizer] and "
        "[robustness] tables; format: see layerstack_jax.io) and write the designed stack as a stack file "
        "(readable by `layerstack predict`) whose header comments state the merit before and after, every "
        "target's result and the yield. Exit status 0 when every target is met (and the yield reaches "
        "min_yield), 1 when not, 2 for a bad input.",
    )
    p.add_argument("design", metavar="DESIGN.toml", help="design file (format: see layerstack_jax.io)")
    p.add_argument("--output", "-o", required=True, metavar="OUT.toml", help="designed stack file to write")
    p.add_argument("--plot", metavar="OUT.png", help="also plot the targets against the design (PNG)")
    p.add_argument("--float32", action="store_true", help="compute in float32 (default: float64)")
    p.set_defaults(func=_cmd_design)


def _cmd_design(args) -> int:
    from datetime import datetime

    from .io import save_stack

    with _precision(args.float32):
        from fitting._design_file import design_report, design_stack_dict, load_design, plot_design, run_design

        design = load_design(args.design)
        outcome = run_design(design)
        report = design_report(outcome)
        out = Path(args.output)
        stamp = datetime.now().isoformat(timespec="seconds")
        header = "\n".join([f"Designed by `layerstack design {args.design}` on {stamp}.", *report])
        save_stack(out, design_stack_dict(outcome, out.parent), header=header)
        print("\n".join(report))
        n = len(outcome.stack.layers)
        print(f"{PROG}: wrote {out} ({n} layer{'' if n == 1 else 's'}) in {outcome.seconds:.1f} s")
        if args.plot:
            plot = plot_design(outcome, args.plot)
            print(f"{PROG}: wrote {plot} (targets vs design)")
    return 0 if outcome.met else 1


_SUBCOMMANDS = (_add_predict_parser, _add_fit_parser, _add_design_parser)


def _build_parser() -> argparse.ArgumentParser:
    from . import __version__

    parser = argparse.ArgumentParser(prog=PROG, description="Light in layered coatings (layerstack_jax).")
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for add in _SUBCOMMANDS:
        add(sub)
    return parser


def _os_error_message(e: OSError) -> str:
    if e.filename is not None and e.strerror:
        return f"{e.filename}: {e.strerror}"
    return str(e)


def main(argv=None) -> int:
    """Run the command line with ``argv`` (default ``sys.argv[1:]``); returns the exit status
    (0 success, 2 usage or input error) instead of exiting, so it can be called in-process."""
    parser = _build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:  # argparse usage errors (status 2), --help / --version (0)
        return e.code if isinstance(e.code, int) else (0 if e.code is None else 2)
    try:
        return args.func(args)
    except LayerstackError as e:
        print(f"{PROG}: error: {e}", file=sys.stderr)
    except OSError as e:
        print(f"{PROG}: error: {_os_error_message(e)}", file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main())
