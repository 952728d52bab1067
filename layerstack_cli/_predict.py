"""``layerstack predict STACK.toml -g GEOM ... -o out.csv [--plot out.png] [--vary LAYER.FIELD=START:STOP:STEP ...]``."""

from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

from layerstack_jax import DEFAULT_NODES, Ellipsometric, LayerstackError, check_stack, reflectance
from layerstack_jax.io import (check_instrument_used, instrument_geometry, load_instrument, load_stack, parse_values,
                               parse_wavelengths, save_spectra_csv)

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


def _predict_batch(args, stack, wavelength, requested) -> tuple[dict, dict]:
    """Columns ``{GEOM? name=value ...: (wl,)}`` of every sample of ``--vary``/``--vary-table``,
    computed by :func:`layerstack_jax.predict` (batched, chunked: bounded memory)."""
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
    labels = [_sample_label(names, row) for row in values]
    if len(set(labels)) != len(labels):
        raise LayerstackError("two samples have the same values (to 12 digits): "
                              f"{next(x for x in labels if labels.count(x) > 1)}")
    columns, geometries = {}, {}
    for gname, geometry in requested:
        try:
            spectra = predict(batched, wavelength, geometry, batch_shape=(values.shape[0],), nodes=args.nodes,
                              chunk=args.chunk)
        except LayerstackError as e:
            raise LayerstackError(f"geometry {gname!r}: {e}") from None
        for label, spectrum in zip(labels, np.asarray(spectra, dtype=float)):
            key = label if len(requested) == 1 else f"{gname} {label}"
            columns[key] = spectrum
            geometries[key] = geometry
    return columns, geometries


def _cmd_predict(args) -> int:
    start = time.perf_counter()
    wavelength = parse_wavelengths(args.wavelengths)
    requested = _parse_geometries(args.geometry)
    with _precision(args.float32):
        stack = load_stack(args.stack)
        settings = load_instrument(args.stack)  # the stack file's [instrument], if any: each geometry takes its keys
        requested = [(name, instrument_geometry(g, settings, partial=True)) for name, g in requested]
        ellipsometers = [instrument_geometry(Ellipsometric(angle, "psi"), settings, partial=True)
                         for angle in args.ellipsometry or ()]
        check_instrument_used(settings, [g for _, g in requested] + ellipsometers)
        try:
            check_stack(stack, wavelength)  # tables cover the grid? (checked once, before any geometry)
        except LayerstackError as e:
            raise LayerstackError(f"{args.stack}: {e}") from None
        if args.polarization and not any(g.supports_polarization for _, g in requested):
            raise LayerstackError("--polarization needs at least one brdf:I:V geometry")
        columns, geometries = {}, {}
        if args.vary or args.vary_table:
            columns, geometries = _predict_batch(args, stack, wavelength, requested)
            requested = []
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


