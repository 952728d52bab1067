"""``layerstack fit STACK.toml DATA.csv -g GEOM -o result.json [--plot fit.png]``."""

from __future__ import annotations

import dataclasses
import time
import warnings
from pathlib import Path
from typing import Optional

import numpy as np

from layerstack_jax import DEFAULT_NODES, LayerstackError, LayerstackWarning
from layerstack_jax.io import instrument_geometry, load_instrument, parse_wavelengths

from ._common import PROG, _positive_int, _precision, _resolve_geometry

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
    p.add_argument("data", metavar="DATA", help="measured spectra: a CSV (wavelength_nm, then one column per spectrum) "
                   "or an instrument file (Woollam .dat, Sentech .txt, Accurion, NeXus .nxs, JCAMP-DX): geometry and "
                   "angles then come from the file")
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
    p.add_argument("--residuals", choices=RESIDUAL_KINDS, default=None, metavar="KIND",
                   help="for a psi/Delta instrument file: what is compared with the model: NCS (default; N = cos 2psi, "
                        "C = sin 2psi cos Delta, S = sin 2psi sin Delta), psi-delta (degrees; Delta residuals wrapped into "
                        "(-180, 180]; the default when the model's reading is depolarized: thick incoherent layers, a "
                        "bandwidth or a thickness spread) or rho (Re and Im of rho = rp/rs = tan psi e^{-i Delta}); the file's sigma(psi), "
                        "sigma(Delta) are propagated to first order; --sigma is then in that kind's unit")
    p.add_argument("--report", choices=("summary", "all"), default="summary",
                   help="with several spectra: one summary table (default) or every fit's full report")
    p.set_defaults(func=_cmd_fit)


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
        chi = f"chi2/nu {r.reduced_chi2:.3g}" if getattr(r, "sigma_given", False) else "chi2 n/a (no sigma)"
        lines.append(f"{name:>16}  {ok:13}  {chi}  " + "  ".join(params))
    return lines


#: residual kinds of a ψ/Δ file (``--residuals``), each a tuple of ``Ellipsometric`` quantities
RESIDUAL_KINDS = ("NCS", "psi-delta", "rho")
_RESIDUAL_QUANTITIES = {"NCS": ("N", "C", "S"), "psi-delta": ("psi", "delta"), "rho": ("rho_re", "rho_im")}


def _rho_parts(psi_deg, delta_deg, sigma_psi_deg=None, sigma_delta_deg=None):
    r"""Re ρ = tan ψ cos Δ and Im ρ = −tan ψ sin Δ of :math:`\rho = r_p/r_s = \tan\psi\,e^{-i\Delta}`
    (the library's convention, ``Measurement.rho()``; Δ as instruments report it), and their σ by
    first-order propagation of σψ, σΔ (degrees; taken as uncorrelated):
    σ_Re = hypot(sec²ψ cos Δ σψ, tan ψ sin Δ σΔ), σ_Im = hypot(sec²ψ sin Δ σψ, tan ψ cos Δ σΔ), ψ, Δ, σ in radians."""
    psi, delta = np.deg2rad(psi_deg), np.deg2rad(delta_deg)
    tan, sec2 = np.tan(psi), 1.0 / np.cos(psi) ** 2
    values = (tan * np.cos(delta), -tan * np.sin(delta))
    if sigma_psi_deg is None:
        return values, (None, None)
    sp, sd = np.deg2rad(sigma_psi_deg), np.deg2rad(sigma_delta_deg)
    sigmas = (np.hypot(sec2 * np.cos(delta) * sp, tan * np.sin(delta) * sd),
              np.hypot(sec2 * np.sin(delta) * sp, tan * np.cos(delta) * sd))
    floor = 1e-6  # a point with a zero propagated σ (ψ = 0) keeps a finite weight
    return values, tuple(np.maximum(s, floor) for s in sigmas)


def _ellipsometric_data(kind, psi_deg, delta_deg, sigma_psi_deg=None, sigma_delta_deg=None):
    """``(values, sigmas)`` of the ``--residuals`` kind, one array per quantity of
    ``_RESIDUAL_QUANTITIES[kind]`` (σ None when the file gives none)."""
    if kind == "NCS":
        return _nsc(psi_deg, delta_deg, sigma_psi_deg, sigma_delta_deg)
    if kind == "rho":
        return _rho_parts(psi_deg, delta_deg, sigma_psi_deg, sigma_delta_deg)
    return (psi_deg, delta_deg), (sigma_psi_deg, sigma_delta_deg)


def _nsc(psi_deg, delta_deg, sigma_psi_deg=None, sigma_delta_deg=None):
    """N = cos 2ψ, C = sin 2ψ cos Δ, S = sin 2ψ sin Δ (wrap-free: a Δ reported in [0, 360) or
    crossing ±180° gives the same values) and their σ by linear propagation of σψ, σΔ."""
    psi, delta = np.deg2rad(psi_deg), np.deg2rad(delta_deg)
    values = (np.cos(2 * psi), np.sin(2 * psi) * np.cos(delta), np.sin(2 * psi) * np.sin(delta))
    if sigma_psi_deg is None:
        return values, (None, None, None)
    sp, sd = np.deg2rad(sigma_psi_deg), np.deg2rad(sigma_delta_deg)
    c2, s2 = np.cos(2 * psi), np.sin(2 * psi)
    sigmas = (np.abs(2 * s2 * sp),
              np.hypot(2 * c2 * np.cos(delta) * sp, s2 * np.sin(delta) * sd),
              np.hypot(2 * c2 * np.sin(delta) * sp, s2 * np.cos(delta) * sd))
    floor = 1e-6  # a point with σ = 0 in N, C or S (e.g. ψ = 45°) keeps a finite weight
    return values, tuple(np.maximum(s, floor) for s in sigmas)


def _default_residuals(m, args, stack, settings, params) -> Optional[str]:
    """What a ψ/Δ file is compared in when ``--residuals`` is not given: N, C, S, unless the
    model's reading is depolarized (thick incoherent layers, the ``[instrument]``'s bandwidth or
    thickness spread, set or free: :meth:`~layerstack_jax.Ellipsometric.depolarizes`). N, C, S
    made from a file's ψ, Δ have length 1, which a depolarized reading (length < 1, ψ and Δ
    reported from it) cannot match — the fit would be biased (a bare glass plate with its
    backside: n(633 nm) 1.493 instead of 1.516); ψ and Δ are then compared as the instrument
    reports them. An explicit ``--residuals NCS`` with such a model is warned about, and so is a
    ``--sigma`` given without ``--residuals`` when the default is ψ/Δ (it is then in degrees)."""
    from layerstack_jax import Ellipsometric

    if m.quantity != "psi_delta":
        return args.residuals
    free = {p.path[-1] for p in params if p.path[:1] == ("datasets",)}
    depolarized = (bool(free & {"bandwidth_nm", "thickness_spread"})
                   or instrument_geometry(Ellipsometric(float(np.asarray(m.angles_deg)[0]), "N"), settings).depolarizes(stack))
    if depolarized and args.residuals == "NCS":
        warnings.warn(f"{args.data}: the model's reading is depolarized (thick incoherent layers, a bandwidth or a "
                      "thickness spread) while N, C, S made from the file's psi/Delta have length 1: the fit is "
                      "biased; --residuals psi-delta compares psi and Delta as the instrument reports them",
                      LayerstackWarning, stacklevel=2)
    if depolarized and args.residuals is None and args.sigma is not None:
        warnings.warn(f"{args.data}: the model's reading is depolarized, so psi and Delta are compared (not N, C, S): "
                      f"--sigma {args.sigma:g} is taken in degrees", LayerstackWarning, stacklevel=2)
    return args.residuals or ("psi-delta" if depolarized else "NCS")


def _measurement_datasets(m, args, kind: Optional[str] = None) -> tuple[list, str, str]:
    """Datasets of an instrument file, one per angle and quantity, with the file's σ; the
    geometry is the file's (ellipsometer or spectrophotometer at the file's angles); ``kind``:
    how ψ/Δ are compared (:data:`RESIDUAL_KINDS`; default ``--residuals``, else N, C, S)."""
    import fitting
    from layerstack_jax import Ellipsometric, Specular

    name = Path(args.data).name
    valid = m.valid()
    datasets = []
    kind = kind or getattr(args, "residuals", None)
    if getattr(args, "residuals", None) is not None and m.quantity != "psi_delta":
        raise LayerstackError(f"{args.data}: --residuals chooses how psi/Delta are compared; this file holds "
                              f"{m.quantity}")
    if m.quantity == "psi_delta":
        kind = kind or "NCS"
        quantities = _RESIDUAL_QUANTITIES[kind]
        sig = (None, None) if m.sigma is None else (m.sigma[:, 0], m.sigma[:, 1])
        values, sigmas = _ellipsometric_data(kind, m.psi_deg, m.delta_deg, *sig)
        for i, angle in enumerate(np.asarray(m.angles_deg, float)):
            for q, y, sq in zip(quantities, values, sigmas):
                sigma = args.sigma if args.sigma is not None else (None if sq is None else np.where(valid[i], sq[i], 1.0))
                datasets.append(fitting.Dataset(Ellipsometric(angle, q), np.where(valid[i], y[i], 0.0), sigma=sigma,
                                                mask=valid[i], name=f"{name} {q} {angle:g} deg"))
        label = "ellipsometry:" + ",".join(f"{a:g}" for a in m.angles_deg) + ":" + ",".join(quantities)
        origin = {"NCS": "from the file (psi/Delta fitted as N, C, S: free of Delta's wrap and of its reporting range)",
                  "psi-delta": "from the file (psi/Delta fitted as psi, Delta in degrees; Delta residuals wrapped "
                               "into (-180, 180])",
                  "rho": "from the file (psi/Delta fitted as Re, Im of rho = rp/rs = tan psi e^{-i Delta}: free of "
                         "Delta's wrap)"}[kind]
    elif m.quantity in ("reflectance", "transmittance"):
        q = "R" if m.quantity == "reflectance" else "T"
        for i, angle in enumerate(np.asarray(m.angles_deg, float)):
            sigma = args.sigma if args.sigma is not None else (None if m.sigma is None else m.sigma[i])
            datasets.append(fitting.Dataset(Specular(angle, q), np.where(valid[i], m.values[i], 0.0), sigma=sigma,
                                            mask=valid[i], name=f"{name} {q} {angle:g} deg"))
        label = "specular:" + ",".join(f"{a:g}" for a in m.angles_deg) + f":{q}"
        origin = "from the file"
    else:
        raise LayerstackError(f"{args.data}: fitting a {m.quantity} measurement from the command line is not supported "
                              "yet (psi/Delta, reflectance and transmittance are); fit it in Python with fitting.Dataset")
    return datasets, label, origin


def _cmd_fit_measurement(args, m, start: float) -> int:
    """``layerstack fit MODEL.toml MEASUREMENT`` for an instrument file: one joint fit of all its
    angles and quantities."""
    import json

    if args.joint or args.background or args.columns:
        raise LayerstackError(f"{args.data}: --joint, --background and --columns apply to CSV spectra, not to an "
                              "instrument file (all its angles are fitted together)")
    if args.geometry is not None:
        raise LayerstackError(f"{args.data}: the file says how it was measured; -g is for CSV spectra")
    grid = np.asarray(m.wavelength_nm, float) if args.wavelengths is None else parse_wavelengths(args.wavelengths)
    with _precision(args.float32):
        import fitting

        stack, params = fitting.load_fit_parameters(args.stack)
        settings = load_instrument(args.stack)  # the stack file's [instrument]: offsets, bandwidth …
        datasets, label, origin = _measurement_datasets(m, args, _default_residuals(m, args, stack, settings, params))
        datasets = [dataclasses.replace(d, geometry=instrument_geometry(d.geometry, settings)) for d in datasets]
        if args.wavelengths is not None:
            datasets = [fitting.Dataset(d.geometry, d.data, sigma=d.sigma, mask=d.mask, name=d.name,
                                        wavelength_nm=np.asarray(m.wavelength_nm, float)) for d in datasets]
        try:
            obj = fitting.Objective(stack, grid, datasets, params, nodes=args.nodes)
        except LayerstackError as e:
            raise LayerstackError(f"{args.data}: {e}") from None
        result = fitting.fit(obj, args.method, starts=args.starts, max_steps=args.max_steps)
    sigma_origin = _sigma_origin(args) if args.sigma is not None or m.sigma is None else "from the file"
    print(f"geometry: {label} ({origin})\nsigma: {sigma_origin}")
    print(result.report())
    out = Path(args.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    payload = {"stack": str(args.stack), "data": str(args.data), "format": m.file_format, "geometry": label,
               "geometry_origin": origin, "sigma": args.sigma, "sigma_origin": sigma_origin,
               "fits": [{"spectrum": Path(args.data).name, **result.to_dict()}]}
    out.write_text(json.dumps(payload, indent=1))
    print(f"{PROG}: wrote {out} (1 fit, {'converged' if result.converged else 'NOT converged'}) in "
          f"{time.perf_counter() - start:.1f} s")
    if args.plot:
        plot = Path(args.plot)
        result.plot(plot, title=f"{Path(args.stack).name} — {label}")
        print(f"{PROG}: wrote {plot} (data vs fit)")
    return 0 if result.converged else 1


def _quantity_from_columns(text: str, names: list, source: str):
    """``(Geometry, origin)`` for a ``-g`` spelling that leaves the quantity open (``specular:θ``
    reads R, T or A: its ``prediction_columns`` are several): the quantity that every data
    column's name states (``R_…``, ``T sheet 1``, ``transmittance …``), never a default — a
    :class:`LayerstackError` when the names do not say or disagree."""
    import re

    from layerstack_jax import parse_geometry

    options = parse_geometry(text).prediction_columns(text)  # [("R_0", Specular(0, "R")), ("T_0", ...), ...]
    tokens = {col.split("_")[0].upper(): g for col, g in options}

    def stated(name: str):
        token = re.split(r"[_\s:()\-]", name.strip(), maxsplit=1)[0].upper()
        if token in tokens:
            return token
        return next((t for t, g in tokens.items() if name.strip().lower().startswith(g.quantity_label)), None)

    found = {stated(n) for n in names}
    if len(found) == 1 and None not in found:
        g = tokens[found.pop()]
        return g, f"-g {text}, {g.quantity_label} from the data's column names"
    quantities = ", ".join(f"{t} ({g.quantity_label})" for t, g in tokens.items())
    why = ("the column names name several of them" if len(found - {None}) > 1
           else "the column names do not say (name them e.g. " + ", ".join(f"{t}_1" for t in tokens) + ")")
    raise LayerstackError(f"{source}: -g {text} does not say which quantity the spectra are: {quantities}; {why}; "
                          f"give it in the geometry, e.g. -g {text}:{next(iter(tokens))}")


def _check_per_sample_values(params, names: list, source: str) -> None:
    """Per-sample values written in the stack file (``value = [...]``) must number the spectra
    of a joint fit."""
    for p in params:
        v = None if p.value is None else np.asarray(p.value)
        if p.per_sample and v is not None and v.ndim == 1 and v.size != len(names):
            raise LayerstackError(f"{source}: {p.name} has {v.size} per-sample values but the joint fit has "
                                  f"{len(names)} spectra ({', '.join(names)}): give one value per spectrum, in the "
                                  "columns' order")


def _read_spectra(path):
    """``(wavelength_nm, columns)`` when ``path`` is a spectra CSV (``wavelength_nm`` then one
    column per spectrum), else None (an instrument file); the file is read once."""
    from layerstack_jax.io import read_spectra_csv, sniff_format

    if sniff_format(path) != "csv":
        return None
    try:
        return read_spectra_csv(path)
    except LayerstackError:
        return None


def _cmd_fit(args) -> int:
    import json

    from layerstack_jax.io import read_measurement

    start = time.perf_counter()
    if not Path(args.data).is_file():
        raise LayerstackError(f"{args.data}: file not found")
    spectra = _read_spectra(args.data)
    if spectra is None:
        return _cmd_fit_measurement(args, read_measurement(args.data), start)
    data_wl, columns = spectra
    if args.residuals is not None:
        raise LayerstackError(f"{args.data}: --residuals applies to psi/Delta instrument files; for CSV spectra name "
                              "the quantity in the geometry (e.g. -g ellipsometry:70:rho_re)")
    geometry, geometry_origin = _resolve_geometry(args.geometry, [n for n in columns if n != args.background],
                                                  source=args.data, origin="from the data's column names",
                                                  silent="the column names do not say")
    if args.geometry is not None and len(geometry.prediction_columns(args.geometry.strip())) > 1:
        geometry, geometry_origin = _quantity_from_columns(args.geometry.strip(),
                                                           [n for n in columns if n != args.background], args.data)
    grid = data_wl if args.wavelengths is None else parse_wavelengths(args.wavelengths)
    geometry = instrument_geometry(geometry, load_instrument(args.stack))
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

        results, skipped = [], []
        if args.joint:
            _check_per_sample_values(params, names, args.stack)
            obj = objective(Y)
            results.append(("+".join(names), fitting.fit(obj, args.method, starts=args.starts, max_steps=args.max_steps)))
        else:
            if any(p.per_sample for p in params):
                raise LayerstackError(f"{args.stack}: per_sample parameters need --joint")
            obj = objective(Y[:1])
            if args.starts == 1 and args.method not in fitting.HOST_METHODS:
                # all columns in one compiled, vmapped solve
                batch = fitting.fit_batch(obj, Y, args.method, max_steps=args.max_steps, full_results=True)
                invalid = dict(getattr(batch, "invalid_data", None) or {})
                for i, (name, r) in enumerate(zip(names, batch.results)):
                    if r is None:  # this column's data failed the checks: flagged, the batch went on
                        skipped.append((name, invalid.get(i, "invalid data")))
                    else:
                        results.append((name, r))
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
    for name, why in skipped:
        print(f"{PROG}: warning: column {name!r} not fitted: {why}")
    out = Path(args.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    payload = {
        "skipped": [{"spectrum": n, "reason": str(w)} for n, w in skipped],
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
    print(f"{PROG}: wrote {out} ({len(results)} fit(s), {n_ok} converged, {len(skipped)} not fitted) in "
          f"{time.perf_counter() - start:.1f} s")
    if args.plot:
        plot = Path(args.plot)
        results[0][1].plot(plot, title=f"{Path(args.stack).name} — {geometry.label}",
                           sample_names=names if args.joint else None)
        print(f"{PROG}: wrote {plot} (data vs fit{' of ' + results[0][0] if len(results) > 1 else ''})")
    return 0 if n_ok == len(results) and not skipped else 1
