"""NeXus/HDF5 files following the NXellipsometry application definition
(both layouts found in the wild: ``entry/sample/measured_data`` with
``entry/instrument/spectrometer/wavelength``, and ``entry/data_collection/measured_data`` with
``wavelength_spectrum`` and ``data_error``); ψ/Δ data only. Needs ``h5py``.
"""

from __future__ import annotations

import re

import numpy as np

from ..._base.validate import LayerstackError
from ..measurement import Measurement
from .common import Format, Head, check_angle, error, unit_of, wavelength_to_nm


def _h5_text(x) -> str:
    v = x[()]
    if isinstance(v, bytes):
        return v.decode("utf-8", "replace")
    if isinstance(v, np.ndarray):
        return ", ".join(s.decode("utf-8", "replace") if isinstance(s, bytes) else str(s) for s in v.ravel())
    return str(v)


def _h5_units(ds) -> str:
    for key in ("units", "unit"):
        if key in ds.attrs:
            u = ds.attrs[key]
            return u.decode() if isinstance(u, bytes) else str(u)
    return ""


def read_nexus(path, *, entry: str = "entry") -> Measurement:
    """Read ψ/Δ from a NeXus/HDF5 file following the NXellipsometry application definition.

    Args:
        path: the ``.nxs``/``.h5`` file.
        entry: name of the NXentry group (default ``"entry"``).

    Returns:
        :class:`Measurement` ``"psi_delta"``: ``measured_data`` ``(ang, 2, wl)`` (leading length-1
        axes dropped), σ from ``data_error`` when numeric, wavelengths converted from the dataset's
        ``units`` attribute (Å, nm, µm, eV) to nm, angles from ``instrument/angle_of_incidence``;
        ``metadata``: sample name, layer structure, description, instrument, definition version.

    Raises:
        LayerstackError: not an HDF5 file, a missing dataset (its path named), a data type other
        than psi/delta, shapes that do not match.
    """
    try:
        import h5py
    except ImportError as err:  # pragma: no cover - depends on the environment
        raise LayerstackError("reading NeXus files needs h5py: pip install 'layerstack-jax[readers]'") from err
    try:
        f = h5py.File(path, "r")
    except OSError as err:
        raise error(path, None, f"not an HDF5/NeXus file ({err})") from None
    with f:
        if entry not in f:
            raise error(path, None, f"no NXentry group {entry!r} (groups: {', '.join(f.keys())})")
        e = f[entry]
        if "data_collection/measured_data" in e:
            keys = ("measured_data", "wavelength_spectrum", "data_type", "data_error")
            data_p, wl_p, type_p, err_p = (f"data_collection/{k}" for k in keys)
        else:  # the legacy layout of NXellipsometry 0.0.2 files
            data_p, wl_p = "sample/measured_data", "instrument/spectrometer/wavelength"
            type_p, err_p = "sample/data_type", "sample/data_error"
        for p in (data_p, wl_p, "instrument/angle_of_incidence"):
            if p not in e:
                raise error(path, None, f"dataset /{entry}/{p} missing (NXellipsometry requires it)")
        data_type = _h5_text(e[type_p]) if type_p in e else "psi/delta"
        if not re.fullmatch(r"\s*psi\s*/\s*delta\s*", data_type, re.IGNORECASE):
            raise error(path, None, f"/{entry}/{type_p} is {data_type!r}; only psi/delta data are supported")
        wl_ds = e[wl_p]
        wl_unit = _h5_units(wl_ds)
        if unit_of(wl_unit) is None:
            raise error(path, None, f"/{entry}/{wl_p} has units {wl_unit!r}; expected angstrom, nm, um or eV")
        wl = wavelength_to_nm(np.asarray(wl_ds, dtype=float).ravel(), wl_unit)
        ang_ds = e["instrument/angle_of_incidence"]
        ang = np.atleast_1d(np.asarray(ang_ds, dtype=float)).ravel()
        ang_unit = _h5_units(ang_ds).lower()
        if ang_unit.startswith("rad"):
            ang = np.rad2deg(ang)
        data = np.asarray(e[data_p], dtype=float)
        while data.ndim > 3 and data.shape[0] == 1:
            data = data[0]
        if data.shape != (ang.size, 2, wl.size):
            raise error(
                path,
                None,
                f"/{entry}/{data_p} has shape {np.shape(e[data_p])}; "
                f"expected (angle, 2, wavelength) = {(ang.size, 2, wl.size)}",
            )
        sigma = None
        if err_p in e and np.issubdtype(e[err_p].dtype, np.number):
            sigma = np.asarray(e[err_p], dtype=float)
            while sigma.ndim > 3 and sigma.shape[0] == 1:
                sigma = sigma[0]
            if sigma.shape != data.shape:
                raise error(path, None, f"/{entry}/{err_p} has shape {sigma.shape}, measured_data {data.shape}")
        meta = [("wavelength_unit", wl_unit)]
        for key in ("definition", "experiment_description", "sample/sample_name", "sample/layer_structure",
                    "instrument/company", "instrument/model", "start_time"):
            if key in e and isinstance(e[key], h5py.Dataset):
                meta.append((key.split("/")[-1], _h5_text(e[key])))
    for a in ang:
        check_angle(path, None, float(a))
    order = np.argsort(wl)
    if np.any(np.diff(wl[order]) <= 0):
        raise error(path, None, f"/{entry}/{wl_p} has repeated wavelengths")
    return Measurement(
        quantity="psi_delta",
        angles_deg=ang,
        wavelength_nm=wl[order],
        values=data[..., order],
        sigma=None if sigma is None else sigma[..., order],
        delta_convention="instrument",
        file_format="nexus",
        source=str(path),
        metadata=tuple(meta),
    )



def _sniff(head: Head) -> bool:
    return head.raw.startswith(b"\x89HDF\r\n\x1a\n") or head.path.suffix.lower() in (".nxs", ".h5", ".hdf5", ".nx5")


FORMAT = Format("nexus", read_nexus, _sniff)
