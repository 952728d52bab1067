"""JCAMP-DX reflectance / transmittance spectra (parsed by the ``jcamp``
package); x in nm, µm or cm⁻¹; absorbance spectra are refused.
"""

from __future__ import annotations

import io
from typing import Optional

import numpy as np

from ..._base.validate import LayerstackError
from ..measurement import Measurement
from .common import (
    Format,
    Head,
    check_angle,
    error,
    read_text,
    unit_of,
    warn_implausible,
    wavelength_to_nm,
)

_JCAMP_QUANTITY = {
    "transmittance": ("transmittance", False),
    "transmission": ("transmittance", False),
    "%t": ("transmittance", True),
    "%transmittance": ("transmittance", True),
    "percent transmittance": ("transmittance", True),
    "reflectance": ("reflectance", False),
    "reflection": ("reflectance", False),
    "%r": ("reflectance", True),
    "%reflectance": ("reflectance", True),
    "percent reflectance": ("reflectance", True),
}


def read_jcamp(path, *, angle_deg: Optional[float] = None, percent: Optional[bool] = None) -> Measurement:
    """Read a JCAMP-DX reflectance or transmittance spectrum (parsed with the ``jcamp`` package).

    Args:
        path: the ``.jdx``/``.dx`` file (one spectrum; AFFN, packed or compressed data).
        angle_deg: angle of incidence in degrees (JCAMP-DX has no field for it): required.
        percent: ``True`` when the values are in % although ``##YUNITS`` says TRANSMITTANCE /
            REFLECTANCE (common in instrument exports); ``None`` (default) follows ``##YUNITS`` and
            refuses values above 1.5 as a probable percent scale.

    Returns:
        :class:`Measurement` ``"reflectance"`` or ``"transmittance"`` ``(1, wl)`` (fractions),
        wavelengths converted from ``##XUNITS`` (nm, µm, 1/cm) to nm and sorted increasing.

    Raises:
        LayerstackError: not JCAMP-DX, absorbance or other y units, x units that are not a
        wavelength, no ``##END=`` or fewer points than ``##NPOINTS`` (truncated), percent values
        in a fraction file, no ``angle_deg``.
    """
    try:
        import jcamp
    except ImportError as err:  # pragma: no cover - depends on the environment
        raise LayerstackError("reading JCAMP-DX files needs jcamp: pip install 'layerstack-jax[readers]'") from err
    lines = read_text(path)
    first = next(((i, ln) for i, ln in enumerate(lines, start=1) if ln.strip()), (1, ""))
    if not first[1].lstrip().startswith("##"):
        raise error(path, first[0], "not a JCAMP-DX file: the first line must be a '##LABEL=' record")
    if not any(ln.strip().upper().startswith("##END") for ln in lines):
        raise error(path, len(lines), "the file ends without '##END=' (truncated?)")
    if sum(ln.strip().upper().startswith("##TITLE") for ln in lines) > 1:
        raise error(path, None, "a compound (LINK) JCAMP-DX file with several blocks; export one spectrum per file")
    try:
        d = jcamp.read(io.StringIO("\n".join(lines)))
    except Exception as err:  # the jcamp parser raises bare Exceptions on corrupt data
        raise error(path, None, f"JCAMP-DX data could not be parsed ({err})") from None
    yunits = str(d.get("yunits", "")).strip()
    key = " ".join(yunits.lower().split())
    key = key.replace(" ", "") if key.replace(" ", "") in _JCAMP_QUANTITY else key
    y_line = next((i for i, ln in enumerate(lines, start=1) if ln.upper().startswith("##YUNITS")), None)
    x_line = next((i for i, ln in enumerate(lines, start=1) if ln.upper().startswith("##XUNITS")), None)
    if key not in _JCAMP_QUANTITY:
        why = f"##YUNITS= {yunits!r}: only reflectance or transmittance spectra can be read (not absorbance or counts)"
        raise error(path, y_line, why)
    quantity, pct = _JCAMP_QUANTITY[key]
    xunits = str(d.get("xunits", "")).strip()
    if unit_of(xunits) is None:
        raise error(path, x_line, f"##XUNITS= {xunits!r} is not a wavelength unit (NANOMETERS, MICROMETERS, 1/CM)")
    x = np.asarray(d.get("x", []), dtype=float)
    y = np.asarray(d.get("y", []), dtype=float)
    npoints = d.get("npoints")
    if x.size == 0 or (npoints is not None and x.size != int(npoints)):
        raise error(path, None, f"##NPOINTS= {npoints} but {x.size} values were read (truncated?)")
    if percent is not None:
        pct = percent
    if pct:
        y = y / 100.0
    elif np.nanmax(y) > 1.5:
        raise error(
            path, y_line,
            f"##YUNITS= {yunits} but the values reach {np.nanmax(y):g}: a fraction cannot; "
            "if the file is in percent, pass percent=True",
        )
    if angle_deg is None:
        raise error(path, None, "JCAMP-DX gives no angle of incidence: pass angle_deg= (e.g. 0 for normal incidence)")
    check_angle(path, None, float(angle_deg))
    wl = wavelength_to_nm(x, xunits)
    order = np.argsort(wl)
    wl, y = wl[order], y[order]
    if np.any(np.diff(wl) <= 0):
        raise error(path, None, "repeated x values")
    meta = tuple(
        (k, str(d[k]))
        for k in ("title", "datatype", "data type", "origin", "owner", "spectrometer/data system", "xunits", "yunits")
        if k in d
    ) + (("angle_source", "given by the caller"), ("percent", str(bool(pct))))
    return warn_implausible(path, Measurement(
        quantity=quantity,
        angles_deg=np.array([float(angle_deg)]),
        wavelength_nm=wl,
        values=y[None, :],
        file_format="jcamp",
        source=str(path),
        metadata=meta,
    ))



def _sniff(head: Head) -> bool:
    return bool(head.lines) and head.lines[0].startswith("##")


FORMAT = Format("jcamp", read_jcamp, _sniff)
