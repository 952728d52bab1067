r"""Readers of instrument files: one module per format, a registry of their sniffing tests, and
:func:`read_measurement` that sniffs the format and reads it.

Every reader returns a :class:`~layerstack_jax._files.measurement.Measurement` in the library's units
(wavelength in nm, angles in degrees, reflectance/transmittance as fractions) with ψ, Δ and
Mueller elements **as the instrument reports them** (``delta_convention="instrument"``, the
convention of Woollam, Sentech and Accurion instruments and of pyElli/refellips, which is the
library's public one). Only units are converted; Δ is not re-wrapped.

Formats (one module each; the details in its docstring)
-------------------------------------------------------
* :mod:`.woollam` — :func:`read_woollam`: J.A. Woollam WVASE / CompleteEASE ASCII exports
* :mod:`.sentech` — :func:`read_sentech`: Sentech SpectraRay ASCII exports
* :mod:`.accurion` — :func:`read_accurion`: Accurion EP3/EP4 nulling-ellipsometer exports
* :mod:`.nexus` — :func:`read_nexus`: NeXus/HDF5 files following the NXellipsometry application definition
* :mod:`.jcamp` — :func:`read_jcamp`: JCAMP-DX reflectance / transmittance spectra
* :mod:`.delimited` — :func:`read_measurement_csv`: plain delimited text

Errors: every problem raises :class:`~layerstack_jax.LayerstackError` naming the file, the line
(or HDF5 dataset) and why.

Adding a format
---------------
One module here with ``read_<format>(path, **options) -> Measurement`` and a line
``FORMAT = Format("<name>", read_<format>, _sniff)`` (:class:`~.common.Format`: ``_sniff(head)``
looks at the file's first bytes and lines, :class:`~.common.Head`), and one line in
:data:`FORMATS` below; the public name is re-exported from :mod:`layerstack_jax.io`.
"""

from __future__ import annotations

from ..measurement import Measurement
from ..._base.validate import LayerstackError
from . import accurion, delimited, jcamp, nexus, sentech, woollam
from .accurion import read_accurion
from .common import HC_EV_NM, Format, Head, wavelength_to_nm
from .delimited import read_measurement_csv, write_measurement_csv
from .jcamp import read_jcamp
from .nexus import read_nexus
from .sentech import read_sentech
from .woollam import read_woollam

__all__ = [
    "read_measurement",
    "read_woollam",
    "read_sentech",
    "read_accurion",
    "read_nexus",
    "read_jcamp",
    "read_measurement_csv",
    "write_measurement_csv",
    "sniff_format",
    "wavelength_to_nm",
    "HC_EV_NM",
    "FORMATS",
    "Format",
]

#: The formats, in the order their sniffing tests are asked; plain CSV (:data:`FALLBACK`) is
#: taken when none says yes.
FORMATS: tuple[Format, ...] = (
    nexus.FORMAT,
    jcamp.FORMAT,
    sentech.FORMAT,
    accurion.FORMAT,
    delimited.FORMAT,
    woollam.FORMAT,
)
FALLBACK = delimited.FORMAT


def sniff_format(path) -> str:
    """The format of an instrument file: ``"nexus"``, ``"jcamp"``, ``"sentech"``, ``"accurion"``,
    ``"woollam"`` or ``"csv"`` (from the first bytes and lines, not the extension alone)."""
    head = Head.of(path)
    for fmt in FORMATS:
        if fmt.sniff(head):
            return fmt.name
    if not head.lines:
        raise LayerstackError(f"{head.path}: empty file")
    return FALLBACK.name


def read_measurement(path, **options) -> Measurement:
    """Read any supported instrument file, choosing the reader from the content (:func:`sniff_format`).

    Args:
        path: the file.
        **options: passed to the reader (``angle_deg``/``percent`` for JCAMP-DX, ``angle_deg``/
            ``quantity`` for CSV, ``entry`` for NeXus); an option the chosen reader does not take
            is an error.

    Returns:
        :class:`Measurement` (module docstring for the conventions).
    """
    name = sniff_format(path)
    reader = next(f.read for f in (*FORMATS, FALLBACK) if f.name == name)
    try:
        return reader(path, **options)
    except TypeError as err:
        if "unexpected keyword" in str(err):
            raise LayerstackError(f"{path}: the {name} reader does not take option(s) {sorted(options)}") from None
        raise
