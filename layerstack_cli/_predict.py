"""``layerstack predict STACK.toml -g GEOM ... -o out.csv [--plot out.png] [--vary LAYER.FIELD=START:STOP:STEP ...]``."""

from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np

from layerstack_jax import DEFAULT_NODES, LayerstackError, check_stack, parse_geometry, reflectance
from layerstack_jax.io import (check_instrument_used, instrument_geometry, instrument_settings, parse_values,
                               parse_wavelengths, read_toml, save_spectra_csv, stack_from_dict)

from ._columns import polarized_columns, supports_polarization
from ._common import PROG, _describe, _parse_geometries, _plot, _positive_int, _positive_int_or_auto, _precision

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
    p.add_argument("--output", "-o", required=True, metavar="OUT",
                   help="file to write, by its suffix: .csv (wavelength_nm, then one column per spectrum); for "
                        "--vary/--vary-table batches also .nc or .zarr (an xarray Dataset: one variable per geometry, "
                        "dims sample x wavelength_nm, the varied fields as coordinates), .npz (numpy arrays with the "
                        "wavelengths and varied values) or .npy (the spectra alone, geometry x sample x wavelength); "
                        f"a CSV holds at most {CSV_MAX_COLUMNS} spectra")
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
                   "as an ellipsometer reads them (with the stack file's [instrument] offsets/bandwidth; a stack with thick "
                   "layers, e.g. a transparent substrate with its backside, also gets depolarization_ANGLE); repeat for "
                   "several angles")
    p.add_argument("--vary", action="append", metavar="LAYER.FIELD=START:STOP:STEP",
                   help="predict a batch of stacks: the value of LAYER.FIELD (the layer's name and key in the stack "
                        "file, e.g. varnish.thickness_nm, varnish.alpha_per_nm, film.n, film.k; or background.rho_g, "
                        "background.n, substrate.n, substrate.k, ambient.n) from START to STOP (included when on the "
                        "grid) by STEP, or a comma list of values, in the file's units. Repeat for several fields: "
                        "every combination is computed (outer product; the last --vary varies fastest). The CSV then "
                        "has one column per sample and geometry, named by the sample's values "
                        "(varnish.thickness_nm=10000; with several geometry columns prefixed 'GEOM ')")
    p.add_argument("--vary-table", metavar="FILE.csv",
                   help="like --vary, one sample per row: a CSV whose header names LAYER.FIELD columns")
    p.add_argument("--chunk", type=_positive_int_or_auto, default="auto", metavar="auto|N",
                   help="with --vary/--vary-table: spectra computed together in one vectorised block; 'auto' "
                        "(default) sizes it from the memory available (at most 8 on CPU), N fixes it")
    p.add_argument("--digits", type=_positive_int, default=10, metavar="N",
                   help="significant digits written in the CSV (default 10; 17 keeps float64 exactly)")
    p.set_defaults(func=_cmd_predict)


# --------------------------------------------------------------------------- batches (--vary)
def _vary_grid(spec: str) -> tuple[str, np.ndarray]:
    """``(name, values)`` of one ``--vary NAME=START:STOP:STEP`` (or ``NAME=v1,v2,...``)."""
    name, sep, grid = spec.partition("=")
    name = name.strip()
    if not sep or not name or not grid.strip():
        raise LayerstackError(f"--vary {spec!r}: write LAYER.FIELD=START:STOP:STEP (e.g. "
                              "varnish.thickness_nm=1e4:5e4:1000) or LAYER.FIELD=v1,v2,...")
    values = parse_values(grid, f"--vary {name}", "1e4:5e4:1000")
    return name, values


def _vary_table(path: str) -> tuple[list, np.ndarray]:
    """``(names, values (samples, fields))`` of a ``--vary-table`` CSV (header: LAYER.FIELD names)."""
    import csv

    p = Path(path)
    if not p.is_file():
        raise LayerstackError(f"{path}: file not found")
    with p.open(newline="", encoding="utf-8") as f:
        rows = [r for r in csv.reader(f) if r and any(c.strip() for c in r) and not r[0].lstrip().startswith("#")]
    if len(rows) < 2:
        raise LayerstackError(f"{path}: need a header of LAYER.FIELD names and at least one row of values")
    names = [c.strip() for c in rows[0]]
    if any(not n for n in names) or len(set(names)) != len(names):
        raise LayerstackError(f"{path}: header names must be non-empty and distinct, got {names}")
    values = np.empty((len(rows) - 1, len(names)))
    for i, row in enumerate(rows[1:], start=2):
        if len(row) != len(names):
            raise LayerstackError(f"{path}: row {i} has {len(row)} values for {len(names)} columns")
        for j, cell in enumerate(row):
            try:
                values[i - 2, j] = float(cell)
            except ValueError:
                raise LayerstackError(f"{path}: row {i}, column {names[j]!r}: {cell.strip()!r} is not a number") from None
            if not np.isfinite(values[i - 2, j]):
                raise LayerstackError(f"{path}: row {i}, column {names[j]!r}: {cell.strip()!r} is not finite")
    return names, values


def _samples(args) -> tuple[list, np.ndarray]:
    """``(names, values (samples, fields))`` from ``--vary`` (outer product) or ``--vary-table``."""
    if args.vary and args.vary_table:
        raise LayerstackError("give --vary or --vary-table, not both")
    if args.vary_table:
        return _vary_table(args.vary_table)
    grids = [_vary_grid(s) for s in args.vary]
    names = [n for n, _ in grids]
    for n in names:
        if names.count(n) > 1:
            raise LayerstackError(f"--vary {n}: given twice")
    mesh = np.meshgrid(*[v for _, v in grids], indexing="ij")
    return names, np.stack([m.ravel() for m in mesh], axis=1)


def _exit_tables() -> set:
    """The stack-file tables of every exit medium the library knows (``substrate``, ``background`` …)."""
    from layerstack_jax import ExitMedium

    found, todo = set(), [ExitMedium]
    while todo:
        cls = todo.pop()
        todo += cls.__subclasses__()
        if isinstance(cls.__dict__.get("table"), str):
            found.add(cls.table)
    return found


def _set_field(stack, name: str, column: np.ndarray, source: str):
    """``stack`` with the file field ``name`` (``LAYER.KEY``, ``ambient.n``, ``substrate.k``,
    ``background.rho_g`` …: a key that a field of the layer, the exit or their index declares,
    :func:`layerstack_jax.file_fields`) set to one value per sample, ``column`` ``(samples,)``,
    as a ``(samples, 1)`` leaf; rebuilt through the constructors, so the values are checked (a
    negative thickness, ρg outside [0, 1] …)."""
    from layerstack_jax import file_fields, replace_at

    owner, dot, key = name.rpartition(".")
    layers = {layer.name: i for i, layer in enumerate(stack.layers)}
    if not dot or not owner:
        raise LayerstackError(f"{name}: write LAYER.FIELD (layers in {source}: {', '.join(layers) or 'none'})")
    values = np.asarray(column, dtype=float)[:, None]
    tables = {"ambient"} | _exit_tables()
    if owner in layers:
        path, what = ("layers", layers[owner]), f"layer {owner!r}"
    elif owner == "ambient":
        path, what = ("ambient",), "[ambient]"
    elif owner == stack.exit.table:
        path, what = ("exit",), f"[{owner}]"
    elif owner in tables:
        raise LayerstackError(f"{name}: {source} has a [{stack.exit.table}], not a [{owner}]")
    else:
        raise LayerstackError(f"{name}: no layer named {owner!r} in {source} (layers: {', '.join(layers) or 'none'}; "
                              f"or {', '.join(f'{t}.FIELD' for t in sorted(tables))})")
    node = stack
    for part in path:
        node = node[part] if isinstance(part, int) else getattr(node, part)
    keys = {k: path + (f,) for k, f in file_fields(node).items()}
    index = getattr(node, "index", None)  # a layer's or an exit's material: its n, k
    if index is not None:
        keys.update({k: path + ("index", f) for k, f in file_fields(index).items() if k not in keys})
    for f in dataclasses.fields(node) if dataclasses.is_dataclass(node) else ():  # one level down: a body's paint
        part = getattr(node, f.name)
        if f.name != "index" and dataclasses.is_dataclass(part):
            keys.update({k: path + (f.name, g) for k, g in file_fields(part).items() if k not in keys})
    if key not in keys:
        hint = "" if index is None or file_fields(index) else (
            f" (its index is a {type(index).__name__}; only numbers n = ..., k = ... can be varied)")
        raise LayerstackError(f"{name}: unknown field {key!r} of {what}; fields: {', '.join(keys)}{hint}")
    old = stack
    for part in keys[key]:
        old = old[part] if isinstance(part, int) else getattr(old, part)
    if old is not None and (callable(old) or np.ndim(old)):
        raise LayerstackError(f"{name}: {key} in {source} is a spectrum or an array; only a number can be varied")
    return replace_at(stack, keys[key], values)


def _sample_label(names: list, row) -> str:
    return " ".join(f"{n}={v:.12g}" for n, v in zip(names, row))


class _Batch(NamedTuple):
    """The spectra of a ``--vary``/``--vary-table`` batch: ``spectra[g]`` ``(samples, wl)`` per
    requested geometry ``g``, one row per sample of the varied fields ``names`` with ``values``
    ``(samples, fields)``."""

    names: list
    values: np.ndarray
    spectra: dict
    geometries: dict


#: Largest number of columns written to a CSV; larger batches go to .nc, .zarr, .npz or .npy.
CSV_MAX_COLUMNS = 2000


def _predict_batch(args, stack, wavelength, requested) -> _Batch:
    """Every sample of ``--vary``/``--vary-table``, computed by :func:`layerstack_jax.predict`
    (batched, chunked: bounded memory; a progress bar on stderr for large batches)."""
    from layerstack_jax import predict

    if args.polarization or args.ellipsometry:
        raise LayerstackError("--vary/--vary-table compute reflectance geometries only; drop --polarization and "
                              "--ellipsometry (or run them on single stacks)")
    names, values = _samples(args)
    batched = stack
    for j, name in enumerate(names):
        try:
            batched = _set_field(batched, name, values[:, j], args.stack)
        except LayerstackError as e:
            msg = str(e)
            raise LayerstackError(msg if msg.startswith(name) else f"{name}: {msg}") from None
    rows = np.unique(values, axis=0)
    if rows.shape[0] != values.shape[0]:
        raise LayerstackError(f"two samples have the same values: {values.shape[0] - rows.shape[0]} repeated row(s)")
    n = values.shape[0]
    spectra, geometries = {}, {}
    for gname, geometry in requested:
        try:
            spectra[gname] = np.asarray(predict(batched, wavelength, geometry, batch_shape=(n,), nodes=args.nodes,
                                                chunk=args.chunk, progress=True if n >= 10_000 else None),
                                        dtype=float)
        except LayerstackError as e:
            raise LayerstackError(f"geometry {gname!r}: {e}") from None
        geometries[gname] = geometry
    return _Batch(names, values, spectra, geometries)


def _batch_columns(batch: _Batch) -> tuple[dict, dict]:
    """The batch as CSV columns ``{[GEOM ]name=value ...: (wl,)}`` (one per sample and geometry)."""
    labels = [_sample_label(batch.names, row) for row in batch.values]
    if len(set(labels)) != len(labels):
        raise LayerstackError("two samples have the same values (to 12 digits): "
                              f"{next(x for x in labels if labels.count(x) > 1)}")
    columns, geometries = {}, {}
    for gname, spectra in batch.spectra.items():
        for label, spectrum in zip(labels, spectra):
            key = label if len(batch.spectra) == 1 else f"{gname} {label}"
            columns[key] = spectrum
            geometries[key] = batch.geometries[gname]
    return columns, geometries


def _write_batch(path: Path, wavelength, batch: _Batch) -> str:
    """Write a batch where users load large arrays, chosen by the suffix of ``path``:

    * ``.nc`` (NetCDF) or ``.zarr``: an xarray Dataset, one variable per geometry (named as spelled,
      ``/`` written ``_``: ``45_0``) with dims ``(sample, wavelength_nm)``, the varied fields as
      coordinates along ``sample``;
    * ``.npz``: arrays ``wavelength_nm``, ``fields`` (names), ``values`` ``(sample, field)`` and
      one ``(sample, wl)`` array per geometry (keys ``reading_0``, …; names in ``geometries``);
    * ``.npy``: the spectra alone, ``(geometry, sample, wl)``.
    Returns a short description of what was written."""
    suffix = path.suffix.lower()
    n = batch.values.shape[0]
    path.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".npy":  # written geometry by geometry: no second copy of the spectra in memory
        shape = (len(batch.spectra), n, np.size(wavelength))
        with open(path, "wb") as f:
            np.lib.format.write_array_header_1_0(f, {"descr": np.lib.format.dtype_to_descr(np.dtype(float)),
                                                     "fortran_order": False, "shape": shape})
            for g in batch.spectra:
                np.ascontiguousarray(batch.spectra[g], dtype=float).tofile(f)
        return f"array (geometry, sample, wavelength) = {shape}"
    described = f"{n} samples x {len(batch.spectra)} geometries"
    if suffix == ".npz":
        arrays = {f"reading_{i}": batch.spectra[g] for i, g in enumerate(batch.spectra)}
        np.savez(path, wavelength_nm=np.asarray(wavelength, float), fields=np.asarray(batch.names),
                 values=batch.values, geometries=np.asarray(list(batch.spectra)), **arrays)
        return described
    import xarray as xr

    coords = {"wavelength_nm": ("wavelength_nm", np.asarray(wavelength, float))}
    coords.update({name: ("sample", batch.values[:, j]) for j, name in enumerate(batch.names)})
    data = {g.replace("/", "_"): (("sample", "wavelength_nm"), batch.spectra[g],
                {"geometry": g, "quantity": batch.geometries[g].quantity_label}) for g in batch.spectra}
    ds = xr.Dataset(data, coords=coords, attrs={"varied": " ".join(batch.names)})
    if suffix == ".zarr":
        ds.to_zarr(path, mode="w", consolidated=False)
    else:
        ds.to_netcdf(path, engine="h5netcdf")
    return described


#: Output formats of ``layerstack predict -o`` by suffix.
OUTPUT_SUFFIXES = (".csv", ".nc", ".zarr", ".npz", ".npy")


def _cmd_predict(args) -> int:
    start = time.perf_counter()
    if Path(args.output).suffix.lower() not in OUTPUT_SUFFIXES:
        raise LayerstackError(f"--output {args.output}: write one of {', '.join(OUTPUT_SUFFIXES)} "
                              "(.nc, .zarr, .npz, .npy for --vary batches)")
    if Path(args.output).suffix.lower() != ".csv" and not (args.vary or args.vary_table):
        raise LayerstackError(f"--output {args.output}: a single stack's spectra are written as .csv; "
                              ".nc, .zarr, .npz and .npy are for --vary/--vary-table batches")
    wavelength = parse_wavelengths(args.wavelengths)
    requested = _parse_geometries(args.geometry)
    with _precision(args.float32):
        raw = read_toml(Path(args.stack))  # read once: the stack and its [instrument]
        stack = stack_from_dict(raw, Path(args.stack).parent, source=args.stack)
        settings = instrument_settings(raw, args.stack)  # the [instrument], if any: each geometry takes its keys
        requested = [(name, instrument_geometry(g, settings, partial=True)) for name, g in requested]
        ellipsometers = [instrument_geometry(parse_geometry(f"ellipsometry:{angle!r}:psi"), settings, partial=True)
                         for angle in args.ellipsometry or ()]  # parsed as spelled: radians are called out
        check_instrument_used(settings, [g for _, g in requested] + ellipsometers)
        try:
            check_stack(stack, wavelength)  # tables cover the grid? (checked once, before any geometry)
        except LayerstackError as e:
            raise LayerstackError(f"{args.stack}: {e}") from None
        if args.polarization and not any(supports_polarization(g) for _, g in requested):
            raise LayerstackError("--polarization needs at least one brdf:I:V geometry")
        columns, geometries = {}, {}
        if args.vary or args.vary_table:
            batch = _predict_batch(args, stack, wavelength, requested)
            if Path(args.output).suffix.lower() != ".csv":
                return _report_batch(args, start, wavelength, batch)
            columns, geometries = _batch_columns(batch)
            if len(columns) > CSV_MAX_COLUMNS:
                raise LayerstackError(f"{args.output}: {len(columns)} spectra are too many for a CSV (at most "
                                      f"{CSV_MAX_COLUMNS} columns); write .nc or .zarr (xarray), .npz or .npy")
            requested = []
        for name, geometry in requested:
            try:
                # Eager (not jitted) on purpose: concrete inputs keep the library's checks,
                # e.g. a wavelength outside a table's range is an error instead of a clamp.
                values = reflectance(stack, wavelength, geometry, nodes=args.nodes)
            except LayerstackError as e:
                raise LayerstackError(f"geometry {name!r}: {e}") from None
            if args.polarization and supports_polarization(geometry):
                try:
                    extra = polarized_columns(geometry, stack, wavelength, name, args.polarization, args.nodes)
                except LayerstackError as e:
                    raise LayerstackError(f"--polarization: {e}") from None
                columns.update(extra)
                geometries.update({k: geometry for k in extra})
                continue
            columns[name] = np.asarray(values, dtype=float)
            geometries[name] = geometry
        for angle, ellipsometer in zip(args.ellipsometry or (), () if args.vary or args.vary_table else ellipsometers):
            try:  # what the ellipsometer reads: depolarized by thick layers, averaged over its non-idealities
                e = ellipsometer.reading(stack, wavelength)
            except LayerstackError as err:
                raise LayerstackError(f"--ellipsometry {angle:g}: {err}") from None
            read = [(f"psi_{angle:g}", e.psi_deg), (f"delta_{angle:g}", e.delta_deg)]
            if not (ellipsometer.ideal and all(stack.coherent)):  # a coherent, ideal reading is not depolarized
                read.append((f"depolarization_{angle:g}", e.depolarization))
            for key, values in read:
                columns[key] = np.asarray(values, dtype=float)
                geometries[key] = None
    bad = [name for name, v in columns.items() if not np.all(np.isfinite(v))]
    if bad:
        print(f"{PROG}: warning: non-finite values in column(s) {', '.join(bad)}", file=sys.stderr)
    out = save_spectra_csv(args.output, wavelength, columns, fmt=f"%.{args.digits}g")
    if len(columns) > 6:
        values = np.stack(list(columns.values()))
        ranges = f"{len(columns)} columns {np.nanmin(values):.4g}..{np.nanmax(values):.4g}"
    else:
        ranges = ", ".join(f"{name} {np.nanmin(v):.4g}..{np.nanmax(v):.4g}" for name, v in columns.items())
    grid = f"{wavelength[0]:g}-{wavelength[-1]:g} nm" if wavelength.size > 1 else f"{wavelength[0]:g} nm"
    elapsed = time.perf_counter() - start
    print(f"{PROG}: wrote {out} ({wavelength.size} wavelengths {grid}; {ranges}) in {elapsed:.1f} s")
    if args.plot and len(columns) > 20:
        print(f"{PROG}: warning: no plot written: {len(columns)} columns (--plot draws up to 20)", file=sys.stderr)
    elif args.plot:
        plot = Path(args.plot)
        plot.parent.mkdir(parents=True, exist_ok=True)
        _plot(plot, wavelength, columns, geometries, title=Path(args.stack).name, subtitle=_describe(stack))
        print(f"{PROG}: wrote {plot} (plot of {len(columns)} spectr{'um' if len(columns) == 1 else 'a'})")
    return 0


def _report_batch(args, start: float, wavelength, batch: _Batch) -> int:
    """Write a batch to .nc/.zarr/.npz/.npy and say what was written."""
    what = _write_batch(Path(args.output), wavelength, batch)
    spectra = list(batch.spectra.values())
    bad = sum(int(np.sum(~np.isfinite(v))) for v in spectra)
    if bad:
        print(f"{PROG}: warning: {bad} non-finite values", file=sys.stderr)
    lo, hi = min(np.nanmin(v) for v in spectra), max(np.nanmax(v) for v in spectra)
    print(f"{PROG}: wrote {args.output} ({what}; {wavelength.size} wavelengths; values {lo:.4g}..{hi:.4g}) "
          f"in {time.perf_counter() - start:.1f} s")
    if args.plot:
        print(f"{PROG}: warning: no plot written for a {batch.values.shape[0]}-sample batch (--plot draws up to 20 "
              "spectra; use a .csv output for small batches)", file=sys.stderr)
    return 0


