"""``layerstack fit STACK.toml DATA.csv -g GEOM -o result.json [--plot fit.png]``."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from layerstack_jax import DEFAULT_NODES, LayerstackError, parse_geometry
from layerstack_jax.io import parse_wavelengths

from ._common import PROG, _positive_int, _precision

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
    p.add_argument("--geometry", "-g", metavar="GEOM",
                   help="measurement geometry of the spectra (see `layerstack predict -h`); needed unless every data "
                        "column is named by its geometry (e.g. 45/0): there is no default")
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
    p.add_argument("--report", choices=("summary", "all"), default="summary",
                   help="with several spectra: one summary table (default) or every fit's full report")
    p.set_defaults(func=_cmd_fit)


def _geometry(args, names: list[str]):
    """The geometry of the data: ``-g``, else the data columns' names when each names the same
    geometry (e.g. ``45/0``); no silent default (it would change the physics)."""
    from layerstack_jax import geometry_kinds

    if args.geometry is not None:
        return parse_geometry(args.geometry), "given (-g)"
    found = set()
    for name in names:
        try:
            found.add(parse_geometry(name).label)
        except LayerstackError:
            found.add(None)
    if len(found) == 1 and None not in found:
        return parse_geometry(found.pop()), "from the data's column names"
    spellings = ", ".join(k.spelling for k in geometry_kinds() if k.spelling)
    raise LayerstackError(f"{args.data}: which geometry were these spectra measured in? give -g GEOM ({spellings}); "
                          "the column names do not say")


def _sigma_origin(args) -> str:
    if args.sigma is not None:
        return f"given (--sigma {args.sigma:g})"
    return "estimated from the residuals (no --sigma): chi2 is not a test of the fit, uncertainties scaled by it"


def _summary(results: list) -> list[str]:
    """One line per fit: values ± standard errors, χ²/ν, converged."""
    lines = []
    for name, r in results:
        params = []
        for key in getattr(r, "values", {}):
            v, e = np.asarray(r.values[key]), np.asarray(r.stderr[key])
            params.append(f"{key} {float(v):.5g} ± {float(e):.2g}" if v.size == 1 else f"{key} [{v.size} values]")
        ok = "converged" if r.converged else "NOT converged"
        lines.append(f"{name:>16}  {ok:13}  reduced chi2 {r.reduced_chi2:.3g}  " + "  ".join(params))
    return lines


def _cmd_fit(args) -> int:
    import json

    from layerstack_jax.io import read_spectra_csv

    start = time.perf_counter()
    data_wl, columns = read_spectra_csv(args.data)
    geometry, geometry_origin = _geometry(args, [n for n in columns if n != args.background])
    grid = data_wl if args.wavelengths is None else parse_wavelengths(args.wavelengths)
    with _precision(args.float32):
        import fitting

        stack, params = fitting.load_fit_parameters(args.stack)
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
        if own_grid is not None:  # every mode resamples the data onto the model grid (never extrapolates)
            Y = fitting.resample(own_grid, Y, grid, what=args.data)
            if args.background is not None:
                columns[args.background] = fitting.resample(own_grid, columns[args.background][None], grid,
                                                            what=args.data)[0]

        def objective(rows):
            ds = [fitting.Dataset(geometry, rows, sigma=args.sigma, name=Path(args.data).name)]
            if args.background is not None:
                ds.append(fitting.Dataset(geometry, columns[args.background], sigma=args.sigma,
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
            if args.starts == 1 and args.method not in fitting.HOST_METHODS:
                # all columns in one compiled, vmapped solve
                batch = fitting.fit_batch(obj, Y, args.method, max_steps=args.max_steps, full_results=True)
                results.extend(zip(names, batch.results))
            else:  # multi-start or a host solver: one fit per column, one compiled solver for all
                results.extend((name, fitting.fit(obj, args.method, data=[y[None]], starts=args.starts,
                                                  max_steps=args.max_steps)) for name, y in zip(names, Y))
    header = [f"geometry: {geometry.label} ({geometry.quantity_label}; {geometry_origin})",
              f"sigma: {_sigma_origin(args)}"]
    print("\n".join(header))
    if len(results) == 1 or args.report == "all":
        for name, r in results:
            print(f"\n### {name}\n{r.report()}")
    else:
        print("\n".join(_summary(results)))
        print(f"({len(results)} fits; --report all prints each fit's full report, the JSON holds them all)")
    out = Path(args.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    payload = {
        "stack": str(args.stack),
        "data": str(args.data),
        "geometry": geometry.label,
        "geometry_origin": geometry_origin,
        "sigma": args.sigma,
        "sigma_origin": _sigma_origin(args),
        "joint": bool(args.joint),
        "background": args.background,
        "fits": [{"spectrum": name, **r.to_dict()} for name, r in results],
    }
    out.write_text(json.dumps(payload, indent=1))
    n_ok = sum(r.converged for _, r in results)
    print(f"{PROG}: wrote {out} ({len(results)} fit(s), {n_ok} converged) in {time.perf_counter() - start:.1f} s")
    if args.plot:
        plot = Path(args.plot)
        results[0][1].plot(plot, title=f"{Path(args.stack).name} — {geometry.label}")
        print(f"{PROG}: wrote {plot} (data vs fit{' of ' + results[0][0] if len(results) > 1 else ''})")
    return 0 if n_ok == len(results) else 1
