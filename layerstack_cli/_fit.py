"""``layerstack fit STACK.toml DATA.csv -g GEOM -o result.json [--plot fit.png]``."""

from __future__ import annotations

import dataclasses
import time
import warnings
from pathlib import Path
from typing import Optional

import numpy as np

from layerstack_jax import DEFAULT_NODES, LayerstackError, LayerstackWarning
from layerstack_jax.io import instrument_geometry, parse_wavelengths

from ._columns import prediction_columns
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
    p.add_argument("data", metavar="DATA", help="measured spectra: a CSV (wavelength_nm, then one column per spectrum; "
                   "comma-, semicolon- or tab-separated, decimal commas with the latter two; empty, NaN or NA cells are "
                   "missing points, left out of the fit; wavelengths increasing or decreasing) or an instrument file "
                   "(Woollam .dat, Sentech .txt, Accurion, NeXus .nxs, JCAMP-DX, a measurement CSV): geometry and "
                   "angles then come from the file; psi/Delta and Mueller-matrix files are fitted (a Mueller matrix by "
                   "the six elements an isotropic sample sets: -M12, -M21 as N, M33, M44 as C, M34, -M43 as S)")
    p.add_argument("--geometry", "-g", metavar="GEOM",
                   help="measurement geometry of the spectra (see `layerstack predict -h`); needed unless every data "
                        "column is named by its geometry (e.g. 45/0): there is no default")
    p.add_argument("--output", "-o", required=True, metavar="OUT.json", help="JSON results to write")
    p.add_argument("--plot", metavar="OUT.png", help="also plot data vs fit with residuals (PNG)")
    p.add_argument("--wavelengths", "-w", metavar="GRID",
                   help="model grid (default: the data's wavelengths); data are resampled onto it, never extrapolated")
    p.add_argument("--range", metavar="START:STOP", dest="wl_range",
                   help="fit only the file's wavelengths in [START, STOP] nm (its own points, not resampled)")
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
        datasets, label, origin = _mueller_datasets(m, args, name)
    return datasets, label, origin


#: The elements of a normalised Mueller matrix that an isotropic sample's reading determines,
#: each as (element, Ellipsometric quantity, sign): in the instruments' frame
#: (:mod:`layerstack_jax._instruments.polarimetry`) M/M11 = [[1, -N, 0, 0], [-N, 1, 0, 0], [0, 0, C, S], [0, 0, -S, C]],
#: N, C, S the (depolarized, where the model is) reading of :class:`~layerstack_jax.Ellipsometric`.
_MUELLER_NCS = (("M12", "N", -1.0), ("M21", "N", -1.0), ("M33", "C", 1.0), ("M44", "C", 1.0),
                ("M34", "S", 1.0), ("M43", "S", -1.0))
#: The other elements, fixed for an isotropic sample: not fitted, their deviation reported.
_MUELLER_FIXED = {"M13": 0.0, "M14": 0.0, "M22": 1.0, "M23": 0.0, "M24": 0.0, "M31": 0.0, "M32": 0.0, "M41": 0.0,
                  "M42": 0.0}


def _mueller_datasets(m, args, name: str) -> tuple[list, str, str]:
    """Datasets of a Mueller-matrix file: the six elements an isotropic stack's reading sets
    (:data:`_MUELLER_NCS`: −M12 and −M21 as N, M33 and M44 as C, M34 and −M43 as S), one dataset
    per element and angle with the file's σ, each point masked where the file has no value.
    A matrix not normalised by the file is divided by M11 (σ too)."""
    import fitting
    from layerstack_jax import Ellipsometric

    arrays = m.to_arrays()
    if not m.mueller_normalized:
        m11 = arrays["M11"]
        if np.any(np.isfinite(m11) & (m11 <= 0)):
            raise LayerstackError(f"{args.data}: M11 <= 0 in a Mueller matrix (the reflected intensity)")
        with np.errstate(invalid="ignore"):
            arrays = {k: (v / m11 if k[:1] == "M" or k.startswith("sigma_") else v) for k, v in arrays.items()}
    datasets = []
    for i, angle in enumerate(np.asarray(m.angles_deg, float)):
        for element, q, sign in _MUELLER_NCS:
            y = sign * arrays[element][i]
            ok = np.isfinite(y)
            sq = arrays.get(f"sigma_{element}")
            sigma = args.sigma if args.sigma is not None else (
                None if sq is None else np.where(ok, np.maximum(np.abs(sq[i]), 1e-6), 1.0))
            datasets.append(fitting.Dataset(Ellipsometric(angle, q), np.where(ok, y, 0.0), sigma=sigma, mask=ok,
                                            name=f"{name} {'-' if sign < 0 else ''}{element} as {q} {angle:g} deg"))
    fixed = np.concatenate([(arrays[k] - v).ravel() for k, v in _MUELLER_FIXED.items()])
    fixed = fixed[np.isfinite(fixed)]
    label = "ellipsometry:" + ",".join(f"{a:g}" for a in m.angles_deg) + ":N,C,S"
    origin = ("from the file's Mueller matrix: -M12, -M21 fitted as N, M33, M44 as C, M34, -M43 as S; the other nine "
              "elements (0, and M22 = 1, for an isotropic sample) are not fitted: their rms deviation from those values "
              f"is {np.sqrt(np.mean(fixed ** 2)) if fixed.size else float('nan'):.3g}")
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
    if args.wl_range is not None:  # --range: the file's own points, not resampled
        _in_range(m.wavelength_nm, args)
        m = m.between(*_parse_range(args.wl_range))
    grid = np.asarray(m.wavelength_nm, float) if args.wavelengths is None else parse_wavelengths(args.wavelengths)
    with _precision(args.float32):
        import fitting

        stack, params, settings = fitting.load_fit_file(args.stack)  # [instrument]: offsets, bandwidth …
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

    options = prediction_columns(parse_geometry(text), text)  # [("R_0", Specular(0, "R")), ("T_0", ...), ...]
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
    """``(wavelength_nm, columns)`` when ``path`` is a spectra CSV (header ``wavelength_nm``, then
    one column per spectrum; a missing value is NaN), else None (an instrument file or a
    measurement CSV, for :func:`~layerstack_jax.io.read_measurement`). The file is read once, and
    a file that fails its reader fails with that reader's message (file, line, column, why)."""
    from layerstack_jax.io import is_spectra_csv, read_spectra_csv, sniff_format

    if sniff_format(path) != "csv" or not is_spectra_csv(path):
        return None
    return read_spectra_csv(path)


def _parse_range(text) -> tuple[float, float]:
    """``--range START:STOP`` in nm: two finite numbers, START < STOP."""
    parts = str(text).split(":")
    try:
        lo, hi = (float(p) for p in parts)
    except ValueError:
        lo = hi = float("nan")
    if len(parts) != 2 or not (np.isfinite(lo) and np.isfinite(hi) and 0 <= lo < hi):
        raise LayerstackError(f"--range {text!r}: give START:STOP in nm, 0 <= START < STOP (e.g. 400:820)")
    return lo, hi


def _in_range(wl, args) -> np.ndarray:
    """Boolean ``(wl,)``: the file's wavelengths kept by ``--range`` (all without it)."""
    wl = np.asarray(wl, float)
    if args.wl_range is None:
        return np.ones(wl.shape, bool)
    lo, hi = _parse_range(args.wl_range)
    keep = (wl >= lo) & (wl <= hi)
    if not keep.any():
        raise LayerstackError(f"{args.data}: --range {args.wl_range}: no wavelength of the file in [{lo:g}, {hi:g}] nm "
                              f"(it spans {wl.min():g}-{wl.max():g} nm)")
    return keep


def _resample_masked(resample, wl, y, mask, grid, what):
    """Spectra with missing points on another grid: a model point is used only when both
    neighbouring data points are (values NaN elsewhere); ``(values, mask)``."""
    values = resample(wl, np.where(mask, y, 0.0), grid, what=what)
    used = resample(wl, mask.astype(float), grid, what=what) > 1 - 1e-12
    return np.where(used, values, np.nan), used


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
    keep = _in_range(data_wl, args)  # --range: the file's own points, not resampled
    data_wl, columns = data_wl[keep], {n: v[keep] for n, v in columns.items()}
    if args.residuals is not None:
        raise LayerstackError(f"{args.data}: --residuals applies to psi/Delta instrument files; for CSV spectra name "
                              "the quantity in the geometry (e.g. -g ellipsometry:70:rho_re)")
    geometry, geometry_origin = _resolve_geometry(args.geometry, [n for n in columns if n != args.background],
                                                  source=args.data, origin="from the data's column names",
                                                  silent="the column names do not say")
    if args.geometry is not None and len(prediction_columns(geometry, args.geometry.strip())) > 1:
        geometry, geometry_origin = _quantity_from_columns(args.geometry.strip(),
                                                           [n for n in columns if n != args.background], args.data)
    grid = data_wl if args.wavelengths is None else parse_wavelengths(args.wavelengths)
    with _precision(args.float32):
        import fitting

        stack, params, settings = fitting.load_fit_file(args.stack)
        geometry = instrument_geometry(geometry, settings)
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
        used = np.isfinite(Y)  # missing points (NaN, NA, empty cells) are masked, point by point
        bg = None if args.background is None else columns[args.background]
        bg_used = None if bg is None else np.isfinite(bg)
        own_grid = None if args.wavelengths is None else data_wl
        if own_grid is not None:  # every mode resamples the data onto the model grid (never extrapolates)
            Y, used = _resample_masked(fitting.resample, own_grid, Y, used, grid, args.data)
            if bg is not None:
                bg, bg_used = _resample_masked(fitting.resample, own_grid, bg, bg_used, grid, args.data)

        def dataset(y, mask, **kw):
            return fitting.Dataset(geometry, np.where(mask, y, 0.0), sigma=args.sigma,
                                   mask=None if mask.all() else mask, **kw)

        def objective(rows, mask):
            ds = [dataset(rows, mask, name=Path(args.data).name)]
            if bg is not None:
                ds.append(dataset(bg, bg_used, name=f"{args.background} (bare background)", bare=True))
            try:
                return fitting.Objective(stack, grid, ds, params, n_samples=rows.shape[0], nodes=args.nodes)
            except LayerstackError as e:
                raise LayerstackError(f"{args.data}: {e}") from None

        results, skipped = [], []
        if args.joint:
            _check_per_sample_values(params, names, args.stack)
            obj = objective(Y, used)
            results.append(("+".join(names), fitting.fit(obj, args.method, starts=args.starts, max_steps=args.max_steps)))
        else:
            if any(p.per_sample for p in params):
                raise LayerstackError(f"{args.stack}: per_sample parameters need --joint")
            fitted, why_not = {}, {}
            # one objective per pattern of missing points (one for a file without missing points)
            for pattern in np.unique(used, axis=0)[::-1]:
                idx = [i for i in range(len(names)) if np.array_equal(used[i], pattern)]
                if not pattern.any():
                    why_not.update((i, "no measured point (every value missing)") for i in idx)
                    continue
                obj = objective(Y[idx[:1]], pattern[None])
                rows = np.where(pattern, Y[idx], 0.0)
                if args.starts == 1 and args.method not in fitting.HOST_METHODS:
                    # all columns in one compiled, vmapped solve
                    batch = fitting.fit_batch(obj, rows, args.method, max_steps=args.max_steps, full_results=True)
                    invalid = dict(getattr(batch, "invalid_data", None) or {})
                    for k, (i, r) in enumerate(zip(idx, batch.results)):
                        if r is None:  # this column's data failed the checks: flagged, the batch went on
                            why_not[i] = invalid.get(k, "invalid data")
                        else:
                            fitted[i] = r
                else:  # multi-start or a host solver: one fit per column, one compiled solver for all
                    fitted.update((i, fitting.fit(obj, args.method, data=[y[None]], starts=args.starts,
                                                  max_steps=args.max_steps)) for i, y in zip(idx, rows))
            results = [(names[i], fitted[i]) for i in sorted(fitted)]
            skipped = [(names[i], why_not[i]) for i in sorted(why_not)]
            if not results:
                raise LayerstackError(f"{args.data}: no column could be fitted: "
                                      + "; ".join(f"{n}: {w}" for n, w in skipped))
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
