r"""Hyperspectral cubes read lazily, as chunked arrays (``cube`` extra: dask, xarray, zarr, spectral).

Every reader returns an :class:`xarray.DataArray` with dims ``("y", "x", "wavelength")``, a
``wavelength`` coordinate in nm, and a :mod:`dask.array` behind it: nothing is read until a
region is asked for (``cube.isel(y=..., x=...).values``), so a cube larger than memory can be
fitted region by region (:func:`fitting.fit_cube`).

* ENVI (``.hdr`` + binary, any interleave) through :mod:`spectral` — the header's
  ``wavelength`` list (converted to nm when ``wavelength units`` says µm, or when the values are
  below 100, which no visible/NIR band in nm is) and the file memory-mapped;
* zarr stores and NetCDF / HDF5 files through :mod:`xarray` (``engine="h5netcdf"`` for HDF5);
* NumPy ``.npy`` files, memory-mapped (the wavelengths given separately);
* an in-memory NumPy / dask array or an existing DataArray (:func:`as_cube`).

Values are whatever the file holds (reflectance as a fraction, in general); readers never
rescale them. Dimension names of a DataArray are recognised case-insensitively: ``y``/``row``/
``line``/``lines``, ``x``/``col``/``column``/``sample``/``samples``, and ``wavelength``/``band``/
``bands``/``wl``/``lambda``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Optional, Union

import numpy as np

from .._base.validate import LayerstackError

__all__ = ["as_cube", "open_cube", "read_envi", "read_zarr", "read_netcdf", "read_npy", "write_zarr_cube",
           "DEFAULT_CUBE_CHUNKS"]

#: Default dask chunks of a cube: 64 × 64 pixels, all bands (one region of a fit, ~13 MB at 401 λ).
DEFAULT_CUBE_CHUNKS = (64, 64, -1)

_DIM_NAMES = {
    "y": ("y", "row", "rows", "line", "lines"),
    "x": ("x", "col", "cols", "column", "columns", "sample", "samples"),
    "wavelength": ("wavelength", "wavelengths", "wavelength_nm", "band", "bands", "wl", "lambda"),
}


def _require(module: str):
    try:
        return __import__(module)
    except ImportError:  # pragma: no cover - depends on the installation
        raise LayerstackError(f"reading cubes needs {module!r}: pip install 'layerstack-jax[cube]'") from None


def _checked_wavelengths(wl, n_bands: int, where: str) -> np.ndarray:
    w = np.asarray(wl, dtype=float)
    if w.ndim != 1 or w.size != n_bands:
        raise LayerstackError(f"{where}: {w.size} wavelengths for {n_bands} bands")
    if not np.all(np.isfinite(w)) or np.any(w <= 0) or (w.size > 1 and np.any(np.diff(w) <= 0)):
        raise LayerstackError(f"{where}: wavelengths must be finite, > 0 and strictly increasing (nm)")
    return w


def as_cube(data, wavelength_nm=None, *, chunks=DEFAULT_CUBE_CHUNKS, name: str = "reflectance"):
    """A cube ``(y, x, wavelength)`` backed by dask from an array or a DataArray.

    Args:
        data: NumPy / dask array ``(y, x, band)``, or an :class:`xarray.DataArray` with three
            recognised dims (module docstring) in any order.
        wavelength_nm: ``(band,)`` band centres in nm (required for arrays; for a DataArray,
            default its wavelength coordinate).
        chunks: dask chunks ``(y, x, band)`` for arrays not chunked yet (-1: the whole axis).
        name: the DataArray's name.

    Returns:
        :class:`xarray.DataArray` dims ``("y", "x", "wavelength")``, coordinate ``wavelength``
        in nm, dask-backed, float values as stored.
    """
    xr = _require("xarray")
    _require("dask")
    import dask.array as dsa

    if isinstance(data, xr.DataArray):
        if data.ndim != 3:
            raise LayerstackError(f"cube: a DataArray (y, x, wavelength) is needed, got dims {data.dims}")
        rename = {}
        for std, aliases in _DIM_NAMES.items():
            found = [d for d in data.dims if str(d).lower() in aliases]
            if len(found) != 1:
                raise LayerstackError(f"cube: no unique {std!r} dimension among {data.dims} (names: {aliases})")
            rename[found[0]] = std
        arr = data.rename(rename).transpose("y", "x", "wavelength")
        wl = arr["wavelength"].values if wavelength_nm is None and "wavelength" in arr.coords else wavelength_nm
        if wl is None:
            raise LayerstackError("cube: the DataArray has no wavelength coordinate; give wavelength_nm")
        wl = _checked_wavelengths(wl, arr.sizes["wavelength"], "cube")
        arr = arr.assign_coords(wavelength=("wavelength", wl))
        if arr.chunks is None:
            arr = arr.chunk(dict(zip(("y", "x", "wavelength"), chunks)))
        arr.name = arr.name or name
        arr["wavelength"].attrs.update(units="nm")
        return arr
    if not hasattr(data, "shape") or len(data.shape) != 3:
        raise LayerstackError(f"cube: an array (y, x, band) is needed, got shape {getattr(data, 'shape', None)}")
    if wavelength_nm is None:
        raise LayerstackError("cube: give wavelength_nm (band centres in nm) with an array")
    wl = _checked_wavelengths(wavelength_nm, data.shape[2], "cube")
    arr = data if isinstance(data, dsa.Array) else dsa.from_array(data, chunks=chunks)
    ny, nx = data.shape[:2]
    out = xr.DataArray(arr, dims=("y", "x", "wavelength"), name=name,
                       coords={"y": np.arange(ny), "x": np.arange(nx), "wavelength": wl})
    out["wavelength"].attrs.update(units="nm")
    return out


def read_envi(header: Union[str, os.PathLike], *, image: Optional[str] = None, wavelength_nm=None,
              chunks=DEFAULT_CUBE_CHUNKS):
    """An ENVI cube (header ``.hdr``, any interleave) through :func:`spectral.envi.open`,
    memory-mapped. Band centres from the header's ``wavelength`` (in nm; µm converted, see the
    module docstring) unless ``wavelength_nm`` is given. Returns a cube as :func:`as_cube`."""
    _require("spectral")
    from spectral.io import envi

    try:
        img = envi.open(str(header), image)
    except Exception as e:  # spectral raises its own exception types for bad headers
        raise LayerstackError(f"ENVI cube {header}: {e}") from None
    mm = img.open_memmap(interleave="bip", writable=False)  # (lines, samples, bands), a view: nothing read
    wl = wavelength_nm
    if wl is None:
        centres = getattr(img.bands, "centers", None)
        if not centres:
            raise LayerstackError(f"ENVI cube {header}: no 'wavelength' in the header; give wavelength_nm")
        wl = np.asarray(centres, dtype=float)
        unit = str(img.metadata.get("wavelength units", "")).strip().lower()
        if unit in ("micrometers", "micrometer", "microns", "micron", "um", "µm") or (not unit and wl.max() < 100):
            wl = wl * 1e3
        elif unit not in ("", "nm", "nanometers", "nanometer"):
            raise LayerstackError(f"ENVI cube {header}: unsupported wavelength units {unit!r}")
    cube = as_cube(mm, wl, chunks=chunks)
    cube.attrs.update(source=str(header), format="ENVI")
    return cube


def _pick_variable(ds, variable: Optional[str], where: str):
    if variable is not None:
        if variable not in ds.data_vars:
            raise LayerstackError(f"{where}: no variable {variable!r} (has {list(ds.data_vars)})")
        return ds[variable]
    three = [v for v in ds.data_vars if ds[v].ndim == 3]
    if len(three) != 1:
        raise LayerstackError(f"{where}: {len(three)} three-dimensional variables {three}: name one (variable=)")
    return ds[three[0]]


def read_zarr(store, *, variable: Optional[str] = None, wavelength_nm=None):
    """A cube stored in zarr (read with :func:`xarray.open_zarr`, the store's own chunks).
    ``variable``: the DataArray to use when the store holds several 3-D variables."""
    xr = _require("xarray")
    _require("zarr")
    try:
        ds = xr.open_zarr(store, consolidated=False)
    except Exception as e:
        raise LayerstackError(f"zarr cube {store}: {e}") from None
    cube = as_cube(_pick_variable(ds, variable, f"zarr cube {store}"), wavelength_nm)
    cube.attrs.update(source=str(store), format="zarr")
    return cube


def read_netcdf(path, *, variable: Optional[str] = None, wavelength_nm=None, chunks=DEFAULT_CUBE_CHUNKS,
                engine: Optional[str] = None):
    """A cube in a NetCDF or HDF5 file through :func:`xarray.open_dataset` (``engine``: default
    xarray's choice; ``"h5netcdf"`` reads HDF5), chunked lazily with ``chunks`` (y, x, band)."""
    xr = _require("xarray")
    try:
        ds = xr.open_dataset(path, engine=engine, chunks={})
    except Exception as e:
        raise LayerstackError(f"NetCDF/HDF5 cube {path}: {e}") from None
    var = _pick_variable(ds, variable, f"NetCDF/HDF5 cube {path}")
    cube = as_cube(var, wavelength_nm)
    cube = cube.chunk(dict(zip(("y", "x", "wavelength"), chunks)))
    cube.attrs.update(source=str(path), format="netcdf")
    return cube


def read_npy(path, wavelength_nm, *, chunks=DEFAULT_CUBE_CHUNKS):
    """A ``(y, x, band)`` ``.npy`` file, memory-mapped (nothing read until asked for)."""
    try:
        mm = np.load(path, mmap_mode="r")
    except (OSError, ValueError) as e:
        raise LayerstackError(f"npy cube {path}: {e}") from None
    cube = as_cube(mm, wavelength_nm, chunks=chunks)
    cube.attrs.update(source=str(path), format="npy")
    return cube


def open_cube(source, wavelength_nm=None, *, variable: Optional[str] = None, chunks=DEFAULT_CUBE_CHUNKS):
    """Any supported cube, by file type: ``.hdr`` (ENVI), ``.zarr`` or a zarr directory,
    ``.nc``/``.nc4``/``.h5``/``.hdf5``/``.he5`` (NetCDF/HDF5), ``.npy``; or an array / DataArray
    (:func:`as_cube`). Returns a lazy cube ``(y, x, wavelength)`` (module docstring)."""
    if not isinstance(source, (str, os.PathLike)):
        return as_cube(source, wavelength_nm, chunks=chunks)
    p = Path(source)
    suffix = p.suffix.lower()
    if suffix == ".hdr":
        return read_envi(p, wavelength_nm=wavelength_nm, chunks=chunks)
    if suffix == ".zarr" or (p.is_dir() and ((p / "zarr.json").exists() or (p / ".zgroup").exists())):
        return read_zarr(p, variable=variable, wavelength_nm=wavelength_nm)
    if suffix in (".nc", ".nc4", ".cdf"):
        return read_netcdf(p, variable=variable, wavelength_nm=wavelength_nm, chunks=chunks)
    if suffix in (".h5", ".hdf5", ".he5"):
        return read_netcdf(p, variable=variable, wavelength_nm=wavelength_nm, chunks=chunks, engine="h5netcdf")
    if suffix == ".npy":
        if wavelength_nm is None:
            raise LayerstackError(f"npy cube {p}: give wavelength_nm")
        return read_npy(p, wavelength_nm, chunks=chunks)
    if p.with_suffix(".hdr").exists():
        return read_envi(p.with_suffix(".hdr"), wavelength_nm=wavelength_nm, chunks=chunks)
    raise LayerstackError(f"cube {p}: unknown format (use .hdr, .zarr, .nc, .h5 or .npy)")


def write_zarr_cube(cube, store, wavelength_nm=None, *, name: str = "reflectance", chunks=DEFAULT_CUBE_CHUNKS):
    """Write a cube (anything :func:`as_cube` takes) to a zarr store, chunk by chunk (never
    whole in memory); :func:`read_zarr` reads it back. Returns ``store``."""
    c = as_cube(cube, wavelength_nm, chunks=chunks).rename(name)
    c.to_dataset().to_zarr(store, mode="w", consolidated=False)
    return store
