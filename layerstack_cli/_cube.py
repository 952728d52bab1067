"""``layerstack fit-cube MODEL.toml CUBE -o maps.zarr [-g GEOM] [--mask MASK] [--chunk auto|N] [--scheduler ADDRESS]``.

Fits every pixel spectrum of a hyperspectral cube with the free parameters of a stack file
(the MODEL.toml of ``layerstack fit``) through :func:`fitting.fit_cube`: region by region into
a zarr store of maps, resumable (a killed and restarted command goes on where it stopped),
locally or on a Dask cluster. Then prints a summary table and writes quick-look PNGs of the
maps (each free parameter, its standard error, the reduced chi2 and the pixel status).
"""

from __future__ import annotations

import logging
import time
import warnings
from pathlib import Path

import numpy as np

from layerstack_jax import DEFAULT_NODES, LayerstackError
from layerstack_jax.io import instrument_geometry, parse_wavelengths

from ._common import PROG, _positive_int, _positive_int_or_auto, _precision, _resolve_geometry

#: Unit of a fitted parameter by its kind (``fitting.Parameter.kind``): colour-bar labels.
_UNITS = {"thickness": "nm", "alpha": "1/nm", "rho_g": "dimensionless", "n": "dimensionless",
          "coefficient": "dimensionless"}

#: fit_cube's keywords named in its messages -> the options of this command.
_OPTIONS = {"resume=False": "--restart", "allow_degenerate=True": "--allow-degenerate",
            "negative_sigmas": "--negative-sigmas"}

_MASK_FORMATS = ".npy (2-D array), .zarr (a store holding one 2-D variable) or an ENVI .hdr of one band"


def _add_fit_cube_parser(sub) -> None:
    p = sub.add_parser(
        "fit-cube",
        help="fit every pixel of a hyperspectral cube; maps into a zarr store",
        description="Fit the parameters declared free in the stack file (as for `layerstack fit`) to every pixel "
        "spectrum of a cube (ENVI .hdr, .zarr, NetCDF .nc, HDF5 .h5, or .npy with -w), region by region, into the "
        "zarr store OUT: one map per free parameter, its standard error (<name>_stderr), chi2, reduced_chi2, "
        "converged, bands_used, status and others. A pixel's bad bands (NaN, saturated, below -K sigma) are left "
        "out of its fit; status: 0 fitted, 1 outside the mask, 2/3/4 too few usable bands (NaN, saturated, far "
        "below zero), and, for fits made but not to be trusted as they are (values kept in the maps): 5 "
        "implausible chi2 (with --sigma: above the upper edge of the central 99.9% of the chi2 distribution of "
        "its degrees of freedom), 6 a parameter on a bound, 7 not converged. "
        "A store of the same job is resumed (regions already written are skipped: a killed command, started "
        "again, goes on); --restart overwrites it. Progress (pixels, rate, ETA) is shown on stderr and logged "
        "to OUT.log.",
        epilog="exit status: 0 when every pixel fit made is trustworthy (status 0), 1 when some is not (status 5, 6 "
        "or 7: the maps are written; the 'status' map says which), 2 for an input error (one line naming the file "
        "or key). Quick-look PNGs go "
        "to --quicklook DIR, by default OUT_quicklook/ beside the store (OUT without .zarr): one per map, with "
        "its colour bar in the parameter's unit (nm, 1/nm, dimensionless), colours spanning the 1st-99th "
        "percentile.",
    )
    p.add_argument("model", metavar="MODEL.toml", help="stack file with free parameters (as for `layerstack fit`)")
    p.add_argument("cube", metavar="CUBE", help="the cube: ENVI .hdr, .zarr, .nc, .h5/.hdf5, or .npy (y, x, band) with -w")
    p.add_argument("--output", "-o", required=True, metavar="OUT.zarr", help="zarr store of the maps (created or resumed)")
    p.add_argument("--geometry", "-g", metavar="GEOM",
                   help="measurement geometry of the cube (see `layerstack predict -h`); needed unless the cube's "
                        "metadata has a 'geometry' attribute (zarr/NetCDF) or header key (ENVI): there is no default")
    p.add_argument("--mask", metavar="MASK",
                   help=f"pixels to fit: {_MASK_FORMATS}, shaped (rows, columns) like the cube's image; true or "
                        "non-zero = fit, false or 0 = leave out (status 1)")
    p.add_argument("--chunk", type=_positive_int_or_auto, default="auto", metavar="auto|N",
                   help="region size N x N pixels: the unit of work, of writing and of resuming; 'auto' (default) "
                        "sizes the regions from the memory of the workers (of this process without --scheduler): "
                        "at most 64 x 64, at least 4 regions per worker thread on a large cube; a resumed store "
                        "keeps its own regions")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="run the regions on a Dask cluster: a scheduler address (tcp://host:8786), or 'processes' "
                        "for a local cluster of --workers processes (default: this process)")
    p.add_argument("--workers", type=_positive_int, default=2, metavar="N", help="with --scheduler processes (default 2)")
    p.add_argument("--sigma", type=float, metavar="S",
                   help="standard deviation of every data point; default: none given (chi2 maps are then sums of "
                        "squared residuals, and the standard errors are scaled by each pixel's reduced chi2)")
    p.add_argument("--saturation", type=float, metavar="V",
                   help="a reading >= V is a bad band of its pixel (left out of that pixel's fit)")
    p.add_argument("--negative-sigmas", type=float, default=5.0, metavar="K",
                   help="readings below zero down to -K sigma are kept as noise around a dark reading (sigma: "
                        "--sigma; without it K/5 x 0.01 absolute); further below they are bad bands of their pixel, "
                        "left out of its fit. 0 <= K <= 5; default 5 (the library's own check); 0 drops every "
                        "reading below zero")
    p.add_argument("--wavelengths", "-w", metavar="GRID",
                   help="band centres in nm (start:stop:step or a comma list) for an .npy cube, which has none")
    p.add_argument("--variable", metavar="NAME", help="the cube's variable in a zarr/NetCDF file holding several")
    p.add_argument("--method", default="lm", choices=("lm", "gauss-newton", "dogleg", "bfgs"),
                   help="solver (default lm)")
    p.add_argument("--max-steps", type=_positive_int, default=256, metavar="N", help="solver step limit (default 256)")
    p.add_argument("--batch", type=_positive_int, default=128, metavar="N",
                   help="pixels per compiled solver call (default 128)")
    p.add_argument("--quicklook", metavar="DIR", help="directory of the quick-look PNGs (default OUT_quicklook/)")
    p.add_argument("--no-quicklook", action="store_true", help="write no PNGs")
    p.add_argument("--log", metavar="FILE", help="progress log (default OUT.log beside the store)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--restart", action="store_true", help="overwrite an existing store instead of resuming it")
    p.add_argument("--allow-degenerate", action="store_true",
                   help="fit even when two free parameters cannot be told apart by construction (e.g. an incoherent "
                        "layer's thickness and alpha)")
    p.add_argument("--float32", action="store_true", help="compute in float32 (default: float64)")
    p.add_argument("--nodes", type=_positive_int, default=DEFAULT_NODES, metavar="N",
                   help=f"Gauss-Legendre nodes per angular segment for diffuse integrals (default {DEFAULT_NODES})")
    p.set_defaults(func=_cmd_fit_cube)


# ----------------------------------------------------------------------------- inputs
def _open_cube(args):
    """The lazy cube ``(y, x, wavelength)`` of ``args.cube`` (:func:`layerstack_jax.open_cube`)."""
    from layerstack_jax import open_cube

    path = Path(args.cube)
    if not path.exists():
        raise LayerstackError(f"{args.cube}: file not found")
    wl = None if args.wavelengths is None else parse_wavelengths(args.wavelengths)
    if path.suffix.lower() == ".npy" and wl is None:
        raise LayerstackError(f"{args.cube}: an .npy cube holds no wavelengths: give its band centres with -w GRID")
    try:
        return open_cube(path, wl, variable=args.variable)
    except LayerstackError as e:
        msg = str(e)
        raise LayerstackError(msg if args.cube in msg else f"{args.cube}: {msg}") from None


def _stated_geometry(cube, path: str) -> list[str]:
    """The geometry the cube's own metadata states, as a list of 0 or 1 spelling: the
    ``geometry`` attribute of its variable or of its zarr/NetCDF file, or the ``geometry`` key of
    an ENVI header."""
    value = cube.attrs.get("geometry")
    fmt = cube.attrs.get("format")
    if value is None and fmt == "ENVI":
        from spectral.io import envi

        value = envi.read_envi_header(str(cube.attrs.get("source", path))).get("geometry")
    elif value is None and fmt in ("zarr", "netcdf"):
        import xarray as xr

        opener = xr.open_zarr if fmt == "zarr" else xr.open_dataset
        kwargs = {"consolidated": False} if fmt == "zarr" else {}
        if fmt == "netcdf" and Path(path).suffix.lower() in (".h5", ".hdf5", ".he5"):
            kwargs["engine"] = "h5netcdf"
        with opener(path, **kwargs) as ds:
            value = ds.attrs.get("geometry")
    return [] if value is None else [str(value).strip()]


def _read_mask(path: str, shape: tuple) -> np.ndarray:
    """The boolean ``(rows, columns)`` mask of a file (formats: ``_MASK_FORMATS``); True = fit."""
    p = Path(path)
    if not p.exists():
        raise LayerstackError(f"{path}: mask file not found")
    suffix = p.suffix.lower()
    try:
        if suffix == ".npy":
            m = np.load(p, allow_pickle=False)
        elif suffix == ".zarr" or (p / ".zgroup").exists() or (p / "zarr.json").exists():
            import xarray as xr

            ds = xr.open_zarr(p, consolidated=False)
            two = [v for v in ds.data_vars if ds[v].ndim == 2]
            if len(two) != 1:
                raise LayerstackError(f"{path}: a mask store must hold one 2-D variable, found {two or 'none'}")
            m = ds[two[0]].values
        elif suffix == ".hdr":
            from spectral.io import envi

            img = envi.open(str(p))
            if img.nbands != 1:
                raise LayerstackError(f"{path}: an ENVI mask must have one band, this one has {img.nbands}")
            m = np.asarray(img.open_memmap(interleave="bip", writable=False))[:, :, 0]
        else:
            raise LayerstackError(f"{path}: unknown mask format (use {_MASK_FORMATS})")
    except LayerstackError:
        raise
    except Exception as e:  # numpy / zarr / spectral errors of an unreadable file
        raise LayerstackError(f"{path}: cannot read the mask: {e}") from None
    m = np.asarray(m)
    if m.ndim != 2 or m.shape != tuple(shape):
        raise LayerstackError(f"{path}: the mask is shaped {m.shape}, the cube's image is {tuple(shape)} "
                              "(rows, columns)")
    if m.dtype != bool:
        if not np.issubdtype(m.dtype, np.number) or not np.all(np.isin(m, (0, 1))):
            raise LayerstackError(f"{path}: mask values must be true/false or 1/0, found {np.unique(m)[:5]} "
                                  f"({m.dtype})")
        m = m.astype(bool)
    return m


def _regions_written(out: Path, shape: tuple, chunk) -> tuple[int, int, int]:
    """``(regions written, regions, pixels written)`` of a store from an earlier run: its completion
    markers ``<out>.regions/<iy>_<ix>`` (the layout :func:`fitting.fit_cube` documents). With
    ``chunk="auto"`` the regions are the store's own (its ``chunk`` attribute)."""
    import json

    from fitting import cube_regions

    markers = Path(str(out).rstrip("/") + ".regions")
    if not out.exists() or not markers.is_dir():
        return 0, 0, 0
    if chunk == "auto":
        import xarray as xr

        try:
            tile = tuple(json.loads(xr.open_zarr(out, consolidated=False).attrs["chunk"]))
        except Exception:  # not a store of fit_cube: fit_cube says so
            return 0, 0, 0
    else:
        tile = (chunk, chunk)
    regions = cube_regions(shape, tile)
    done = [(ys.stop - ys.start) * (xs.stop - xs.start) for iy, ix, ys, xs in regions
            if (markers / f"{iy}_{ix}").exists()]
    return len(done), len(regions), sum(done)


def _regions_line(maps) -> str:
    """How the store's regions were sized: ``regions of R x C pixels (...)`` from its attributes."""
    import json

    rows, cols = json.loads(maps.attrs["chunk"])
    sizing = json.loads(maps.attrs.get("chunk_sizing", '"given"'))
    if isinstance(sizing, dict):
        how = (f"auto: budget {sizing['budget_source']}; measured {sizing['per_pixel_bytes'] / 1e3:.4g} kB per pixel, "
               f"{sizing['solver_bytes'] / 1e6:.4g} MB per solver call")
    else:
        how = "given (--chunk)" if sizing == "given" else str(sizing)
    return f"regions of {rows} x {cols} pixels, {maps.attrs.get('chunk_size', '?')} pixels per solver call ({how})"


# ----------------------------------------------------------------------------- outputs
def _units(objective, maps) -> dict:
    """``{map variable: unit}`` of the fitted parameter components (the store's attributes
    ``parameters`` and ``parameter_variables`` pair each component with its map)."""
    import json

    layout = objective.layout
    kinds = {name: layout.params[i].parameter.kind for name, i in zip(layout.names, layout.owner)}
    variables = dict(zip(json.loads(maps.attrs["parameters"]), json.loads(maps.attrs["parameter_variables"])))
    return {variables[name]: _UNITS.get(kind, "unit of the stack file") for name, kind in kinds.items()}


def _summary(maps, sigma_given: bool, bands: int, n_free: int, seconds: float, processed: int) -> list[str]:
    """The end-of-run table: pixels per status (fitted, outside the mask, too few usable bands,
    and the fits made but flagged: implausible chi2, on a bound, not converged), pixels fitted
    with some bands left out, median reduced chi2, χ² below its distribution's central 99.9 %
    (σ given), time and rate. ``bands``: the bands a pixel's fit uses when none is bad;
    ``n_free``: free parameters (a pixel's degrees of freedom: ``bands_used`` − ``n_free``)."""
    from fitting import FIT_MADE

    status = np.asarray(maps["status"].values)
    made = np.isin(status, FIT_MADE)
    count = {c: int((status == c).sum()) for c in range(-1, 8)}
    rows = [("pixels", status.size), ("fitted", count[0]), ("outside the mask", count[1]),
            ("no data (NaN/inf)", count[2]), ("saturated", count[3]), ("far below zero", count[4]),
            ("implausible chi2", f"{count[5]}" + (" (chi2 above the central 99.9% of its distribution: a local "
                                                   "minimum or a wrong model; values kept, see reduced_chi2)"
                                                   if count[5] else "" if sigma_given
                                                   else " (no --sigma: chi2 not tested)")),
            ("on a bound", f"{count[6]}" + (" (a parameter at its min or max: the optimum may lie beyond)"
                                            if count[6] else "")),
            ("NOT converged", count[7])]
    if count[-1]:
        rows.append(("not fitted yet", count[-1]))
    if "bands_used" in maps and made.any():
        rows.append(("fits with bad bands left out", int(np.sum(np.asarray(maps["bands_used"].values)[made] < bands))))
    if "identifiable" in maps:
        rows.append(("not identifiable", int((np.asarray(maps["identifiable"].values)[made] == 0).sum())))
    if made.any():
        chi = np.asarray(maps["reduced_chi2"].values)[made]
        med = f"{np.nanmedian(chi):.4g}" if np.isfinite(chi).any() else "n/a"
        rows.append(("median reduced chi2", med if sigma_given else f"{med} (no --sigma: not a test of the fit)"))
        if sigma_given and "bands_used" in maps:
            from scipy.stats import chi2 as chi2_distribution

            from fitting._cube import CHI2_CENTRAL

            nu = np.asarray(maps["bands_used"].values)[made] - n_free
            low = chi2_distribution.cdf(np.asarray(maps["chi2"].values)[made], np.maximum(nu, 1)) \
                < (1.0 - CHI2_CENTRAL) / 2
            if low.any():
                rows.append(("chi2 too small", f"{int(low.sum())} (below the central 99.9%: --sigma larger than the "
                                               "scatter of the data? standard errors too large)"))
    rows.append(("pixels done this run", processed))
    rows.append(("time (this run)", f"{seconds:.1f} s"))
    rows.append(("pixels/s (this run)", f"{processed / seconds:.4g}" if seconds > 0 else "n/a"))
    width = max(len(k) for k, _ in rows)
    return [f"  {k:<{width}}  {v}" for k, v in rows]


def _quicklook(maps, directory: Path, units: dict, title: str) -> list[Path]:
    """One PNG per map (parameters, their standard errors, reduced chi2, status), each with its
    colour bar labelled in the map's unit; returns the files written. Parameters and standard
    errors are shown where the status is 0 (fitted), reduced chi2 wherever a fit was made (the
    flagged pixels stand out there); other pixels are grey."""
    from matplotlib import colormaps
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.colors import BoundaryNorm, ListedColormap
    from matplotlib.figure import Figure

    from fitting import CUBE_STATUS, FIT_MADE

    directory.mkdir(parents=True, exist_ok=True)
    status = np.asarray(maps["status"].values)
    plots = []
    for var, unit in units.items():
        plots.append((var, f"{var} ({unit})"))
        plots.append((f"{var}_stderr", f"standard error of {var} ({unit})"))
    plots.append(("reduced_chi2", "reduced chi2 (dimensionless)"))
    written = []
    ny, nx = maps.sizes["y"], maps.sizes["x"]
    size = (min(10.0, 2.0 + 6.0 * nx / max(nx, ny)), min(8.0, 1.2 + 6.0 * ny / max(nx, ny)))

    def figure():
        fig = Figure(figsize=size, dpi=100, layout="constrained")
        FigureCanvasAgg(fig)
        return fig, fig.add_subplot()

    for var, label in plots:
        if var not in maps:
            continue
        shown = np.isin(status, FIT_MADE) if var == "reduced_chi2" else status == 0
        values = np.where(shown, np.asarray(maps[var].values, dtype=float), np.nan)
        fig, ax = figure()
        cmap = colormaps["viridis"].with_extremes(bad="0.75")  # pixels not fitted: grey
        finite = values[np.isfinite(values)]
        lo, hi = (np.percentile(finite, [1, 99]) if finite.size else (0.0, 1.0))
        if hi <= lo:
            lo, hi = lo - 0.5 * abs(lo or 1.0), hi + 0.5 * abs(hi or 1.0)
        im = ax.imshow(np.ma.masked_invalid(values), cmap=cmap, vmin=lo, vmax=hi, interpolation="nearest")
        fig.colorbar(im, ax=ax, label=label, extend="both")
        ax.set_xlabel("x (column)")
        ax.set_ylabel("y (row)")
        grey = "no fit made" if var == "reduced_chi2" else "not fitted, or flagged (status map)"
        ax.set_title(f"{title}\n{var} (grey: {grey})", fontsize=9)
        path = directory / f"{var}.png"
        fig.savefig(path)
        written.append(path)
    # status: categorical
    codes = sorted(CUBE_STATUS)
    fig, ax = figure()
    colours = ["0.9", "tab:green", "0.5", "tab:red", "tab:orange", "tab:purple", "tab:pink", "tab:cyan",
               "tab:brown"][:len(codes)]
    cmap = ListedColormap(colours)
    norm = BoundaryNorm([c - 0.5 for c in codes] + [codes[-1] + 0.5], cmap.N)
    im = ax.imshow(status, cmap=cmap, norm=norm, interpolation="nearest")
    bar = fig.colorbar(im, ax=ax, ticks=codes, label="status (code)")
    bar.ax.set_yticklabels([f"{c}: {CUBE_STATUS[c]}" for c in codes], fontsize=7)
    ax.set_xlabel("x (column)")
    ax.set_ylabel("y (row)")
    ax.set_title(f"{title}\nstatus", fontsize=9)
    path = directory / "status.png"
    fig.savefig(path)
    written.append(path)
    return written


class _LogFile(logging.Handler):
    """Appends the records of the ``fitting.cube`` logger (regions done, pixels/s, ETA) to a file."""

    def __init__(self, path: Path):
        super().__init__(logging.INFO)
        self.path = path
        self.setFormatter(logging.Formatter("%(asctime)s %(message)s"))

    def emit(self, record):
        with self.path.open("a", encoding="utf-8") as f:
            f.write(self.format(record) + "\n")


# ----------------------------------------------------------------------------- command
def _cmd_fit_cube(args) -> int:
    start = time.perf_counter()
    out = Path(args.output)
    if not Path(args.model).is_file():
        raise LayerstackError(f"{args.model}: file not found")
    cube = _open_cube(args)
    geometry, origin = _resolve_geometry(args.geometry, _stated_geometry(cube, args.cube), source=args.cube,
                                         origin="from the cube's metadata",
                                         silent="the cube's metadata has no 'geometry'")
    shape = (cube.sizes["y"], cube.sizes["x"])
    mask = None if args.mask is None else _read_mask(args.mask, shape)
    wavelength = np.asarray(cube["wavelength"].values, dtype=float)
    with _precision(args.float32):
        import fitting

        stack, params, settings = fitting.load_fit_file(args.model)
        geometry = instrument_geometry(geometry, settings)
        if not params:
            raise LayerstackError(f"{args.model}: no free parameter (mark one with {{ value = ..., free = true }})")
        if any(p.per_sample for p in params):
            raise LayerstackError(f"{args.model}: per_sample parameters are for joint fits; a cube fits each pixel "
                                  "on its own")
        placeholder = np.zeros(wavelength.size)  # fit_cube uses only the dataset's σ and band mask
        try:
            objective = fitting.Objective(stack, wavelength, [fitting.Dataset(geometry, placeholder, sigma=args.sigma,
                                                                             name=Path(args.cube).name)],
                                          params, nodes=args.nodes)
        except LayerstackError as e:
            raise LayerstackError(f"{args.model}: {e}") from None
        print(f"{PROG}: cube {args.cube}: {shape[0]} x {shape[1]} pixels, {wavelength.size} bands "
              f"({wavelength[0]:g}-{wavelength[-1]:g} nm)")
        print(f"geometry: {geometry.label} ({geometry.quantity_label}; {origin})")
        print("sigma: " + (f"given (--sigma {args.sigma:g})" if args.sigma is not None else
                           "not given: chi2 is a sum of squared residuals, standard errors scaled by it"))
        done_regions, n_regions, done_px = (0, 0, 0) if args.restart else _regions_written(out, shape, args.chunk)
        if done_regions:
            print(f"{PROG}: resuming: {done_regions} of {n_regions} chunks already written "
                  f"({done_px} of {shape[0] * shape[1]} pixels); --restart starts afresh")
        log_path = Path(args.log) if args.log else Path(str(out).rstrip("/") + ".log")
        log_path.parent.mkdir(parents=True, exist_ok=True)
        handler, logger = _LogFile(log_path), logging.getLogger("fitting.cube")
        level = logger.level
        logger.addHandler(handler)
        logger.setLevel(logging.INFO)
        t0 = time.perf_counter()
        try:
            chunk = args.chunk if args.chunk == "auto" else (args.chunk, args.chunk)
            with warnings.catch_warnings():  # the summary below says it, with the counts
                warnings.filterwarnings("ignore", message=r"fit_cube: \d+ pixel fit\(s\) not to be trusted")
                maps = fitting.fit_cube(objective, cube, out=out, mask=mask, chunk=chunk,
                                        saturation=args.saturation, negative_sigmas=args.negative_sigmas,
                                        method=args.method, chunk_size=args.batch,
                                        client=args.scheduler, n_workers=args.workers, resume=not args.restart,
                                        progress=not args.quiet, allow_degenerate=args.allow_degenerate,
                                        max_steps=args.max_steps)
        except LayerstackError as e:  # fit_cube's hints name its keywords: say the command's options
            msg = str(e)
            for keyword, option in _OPTIONS.items():
                msg = msg.replace(keyword, option)
            raise LayerstackError(msg) from None
        finally:
            logger.removeHandler(handler)
            logger.setLevel(level)
        seconds = time.perf_counter() - t0
        maps = maps.load()
        units = _units(objective, maps)
    lines = _summary(maps, args.sigma is not None, wavelength.size, objective.n_parameters, seconds,
                     shape[0] * shape[1] - done_px)
    print(f"{PROG}: wrote {out} ({len(units)} parameter map(s) and their standard errors; progress log {log_path})")
    print(f"{PROG}: {_regions_line(maps)}")
    print("\n".join(lines))
    flagged = np.isin(np.asarray(maps["status"].values), (5, 6, 7))
    if flagged.any():
        print(f"{PROG}: {int(flagged.sum())} pixel fit(s) not to be trusted as they are (status 5 implausible chi2, "
              "6 on a bound, 7 not converged): see the status map; exit status 1")
    if not args.no_quicklook:
        directory = Path(args.quicklook) if args.quicklook else out.with_name(
            (out.name[:-5] if out.name.endswith(".zarr") else out.name) + "_quicklook")
        for path in _quicklook(maps, directory, units, title=f"{Path(args.model).name} — {Path(args.cube).name}"):
            print(f"{PROG}: wrote {path}")
    print(f"{PROG}: done in {time.perf_counter() - start:.1f} s")
    return 1 if flagged.any() else 0
