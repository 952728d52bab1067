"""The zarr store of :func:`fitting.fit_cube`'s maps and its resume bookkeeping: the maps'
zarr-safe names (:func:`_var`) and their "not fitted yet" template (:func:`_empty_maps`), the
store's creation (:func:`_init_store`), a region's maps written (:func:`_write_region`), the
completion markers beside the store (:func:`_mark_done`, :func:`_marker`), the job's
fingerprint that a resumed run must match (:func:`_fingerprint`), and the fitted parameter
vectors read back from the maps (:func:`cube_parameters`)."""

from __future__ import annotations

import hashlib
import os
import re
from pathlib import Path

import numpy as np

from layerstack_jax import LayerstackError

from ._objective import Objective

__all__ = ["cube_parameters"]

_MARKERS = ".regions"  # suffix of the marker directory beside the store
_SAFE = re.compile(r"[^A-Za-z0-9_.\-]+")


def _var(name: str) -> str:
    """A zarr-safe variable name for a parameter component (``varnish.alpha[3]`` → ``varnish.alpha_3``)."""
    return _SAFE.sub("_", name).strip("_") or "parameter"


def cube_parameters(objective: Objective, maps) -> np.ndarray:
    """The fitted parameter vectors of a cube, ``(y, x, P)`` in the order of
    ``objective.layout.names``, from the maps :func:`fitting.fit_cube` wrote (an ``xarray.Dataset``, or
    the path of its zarr store); NaN where no fit was made."""
    if not hasattr(maps, "data_vars"):
        import xarray as xr

        maps = xr.open_zarr(maps)
    names = [_var(n) for n in objective.layout.names]
    missing = [n for n in names if n not in maps.data_vars]
    if missing:
        raise LayerstackError(f"cube_parameters: the maps lack {', '.join(missing)}: were they written by fit_cube "
                              "for this objective?")
    return np.stack([np.asarray(maps[n].values, float) for n in names], axis=-1)


def _empty_maps(shape: tuple, names: tuple) -> dict:
    maps = {}
    for n in names:
        maps[_var(n)] = np.full(shape, np.nan)
        maps[_var(n) + "_stderr"] = np.full(shape, np.nan)
    for n in ("chi2", "reduced_chi2"):
        maps[n] = np.full(shape, np.nan)
    for n, dt in (("num_steps", np.int32), ("result_code", np.int16), ("rank", np.int16), ("converged", np.int8),
                  ("identifiable", np.int8), ("bands_used", np.int16)):
        maps[n] = np.full(shape, -1, dt)
    maps["status"] = np.full(shape, -1, np.int8)
    return maps


def _write_region(out: str, maps: dict, ys: slice, xs: slice) -> None:
    import xarray as xr

    ds = xr.Dataset({k: (("y", "x"), v) for k, v in maps.items()})
    ds.to_zarr(out, region={"y": ys, "x": xs}, consolidated=False)


def _marker_dir(out: str) -> Path:
    return Path(str(out).rstrip("/") + _MARKERS)


def _marker(out: str, iy: int, ix: int) -> Path:
    return _marker_dir(out) / f"{iy}_{ix}"


def _mark_done(out: str, iy: int, ix: int) -> None:
    path = _marker(out, iy, ix)
    path.parent.mkdir(exist_ok=True)
    tmp = path.with_name(path.name + f".{os.getpid()}.tmp")
    tmp.write_text("done\n")
    os.replace(tmp, path)  # atomic: a marker exists only once its region is fully written


def _fingerprint(objective: Objective, cube, chunk: tuple, method: str, chunk_size: int, saturation, mask,
                 fit_options: tuple) -> str:
    """Identity of a job (objective, cube geometry, settings): a store is resumed only by the same job."""
    h = hashlib.sha1()
    lay = objective.layout
    for part in (lay.names, np.asarray(lay.x0), np.asarray(lay.lower), np.asarray(lay.upper),
                 np.asarray(objective.wavelength), np.asarray(cube["wavelength"].values), cube.shape, chunk, method,
                 chunk_size, saturation, fit_options,
                 [np.asarray(w) for w in objective.args()[1]]):
        h.update(repr(part).encode() if not isinstance(part, np.ndarray) else part.tobytes())
    if mask is not None:
        h.update(np.packbits(np.asarray(mask, bool)).tobytes())
    return h.hexdigest()


def _init_store(out: str, cube, names: tuple, chunk: tuple, attrs: dict) -> None:
    """Create the zarr store: every map at its 'not fitted yet' value, chunked like the regions."""
    import dask.array as da
    import xarray as xr

    ny, nx = cube.sizes["y"], cube.sizes["x"]
    template = _empty_maps((1, 1), names)
    ds = xr.Dataset(
        {k: (("y", "x"), da.full((ny, nx), v.reshape(-1)[0], dtype=v.dtype, chunks=chunk)) for k, v in template.items()},
        coords={"y": cube["y"].values, "x": cube["x"].values},
        attrs=attrs,
    )
    encoding = {k: {"chunks": chunk} for k in template}
    markers = _marker_dir(out)
    if markers.exists():  # markers of an earlier job in this place: they no longer describe the store
        for m in markers.iterdir():
            m.unlink()
    ds.to_zarr(out, mode="w", encoding=encoding, consolidated=False)
    markers.mkdir(exist_ok=True)
