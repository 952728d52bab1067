"""What every reader shares: wavelength units, the error form (file, line, why), text and
number parsing, range checks, and the :class:`Format` record by which a reader registers itself
(its name, its reader and its sniffing test)."""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional, Sequence

import numpy as np

from .._measurement import Measurement
from .._validate import LayerstackError

#: h·c/e in eV·nm, from the exact SI constants (h = 6.62607015e-34 J s, c = 299792458 m/s,
#: e = 1.602176634e-19 C): λ[nm] = HC_EV_NM / E[eV].
HC_EV_NM = 6.62607015e-34 * 299792458.0 / 1.602176634e-19 * 1e9


# ---------------------------------------------------------------------------------------------
# units and small helpers
# ---------------------------------------------------------------------------------------------
_UNIT_ALIASES = {
    "nm": "nm",
    "nanometer": "nm",
    "nanometers": "nm",
    "nanometre": "nm",
    "nanometres": "nm",
    "a": "angstrom",
    "å": "angstrom",
    "angstrom": "angstrom",
    "angstroms": "angstrom",
    "um": "um",
    "µm": "um",
    "μm": "um",
    "micron": "um",
    "microns": "um",
    "micrometer": "um",
    "micrometers": "um",
    "micrometre": "um",
    "micrometres": "um",
    "ev": "eV",
    "1/cm": "1/cm",
    "cm-1": "1/cm",
    "cm^-1": "1/cm",
    "cm⁻¹": "1/cm",
    "wavenumber": "1/cm",
    "wavenumbers": "1/cm",
}


def unit_of(text: str) -> Optional[str]:
    """Canonical wavelength unit (``nm``, ``angstrom``, ``um``, ``eV``, ``1/cm``) of a unit word, or None."""
    return _UNIT_ALIASES.get(text.strip().strip(".").lower())


def wavelength_to_nm(x, unit: str) -> np.ndarray:
    """Convert wavelengths (or photon energies, wavenumbers) to vacuum wavelengths in nm.

    Args:
        x: values, any shape.
        unit: ``"nm"``, ``"angstrom"`` (Å), ``"um"`` (µm), ``"eV"`` (photon energy:
            λ = hc/E) or ``"1/cm"`` (wavenumber: λ = 10⁷/ν̃); aliases accepted (``"Angstroms"``, ``"µm"`` …).

    Returns:
        Wavelengths in nm, same shape.
    """
    canon = unit_of(unit) or unit
    x = np.asarray(x, dtype=float)
    if canon == "nm":
        return x
    if canon == "angstrom":
        return x / 10.0
    if canon == "um":
        return x * 1000.0
    if canon == "eV":
        return HC_EV_NM / x
    if canon == "1/cm":
        return 1e7 / x
    raise LayerstackError(f"unknown wavelength unit {unit!r} (nm, Angstroms, um, eV or 1/cm)")


def error(path, line: Optional[int], why: str) -> LayerstackError:
    where = f"{path}, line {line}" if line is not None else f"{path}"
    return LayerstackError(f"{where}: {why}")


def read_text(path) -> list[str]:
    """Lines of a text file (UTF-8, else Latin-1 as instruments on Windows write), without line ends."""
    path = Path(path)
    if not path.is_file():
        raise LayerstackError(f"{path}: no such file")
    raw = path.read_bytes()
    if b"\x00" in raw[:4096]:
        raise error(path, None, "binary file, not a text export (for NeXus/HDF5 use read_nexus)")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")
    return text.replace("\x1a", "").splitlines()


def to_float(token: str) -> Optional[float]:
    """The number a token spells (``1.5``, ``-3e-2``, ``inf``, ``nan``), or None."""
    try:
        return float(token)
    except ValueError:
        return None


def numbers(tokens: Sequence[str]) -> Optional[list[float]]:
    out = [to_float(t) for t in tokens]
    return None if any(v is None for v in out) else out


def check_range(path, line, name: str, value: float, lo: float, hi: float, unit: str = "degrees") -> None:
    if not (math.isfinite(value) and lo <= value <= hi):
        raise error(path, line, f"{name} = {value!r} is not a number in [{lo:g}, {hi:g}] {unit}")


def warn_implausible(path, m: Measurement) -> Measurement:
    """Warn (not fail) when a measurement's values are possible in a file but not in nature:
    R or T beyond [-0.02, 1.02], or normalised Mueller elements beyond ±1.05."""
    v = np.asarray(m.values)
    if m.quantity in ("reflectance", "transmittance"):
        lo, hi = np.nanmin(v), np.nanmax(v)
        if lo < -0.02 or hi > 1.02:
            warnings.warn(
                f"{path}: {m.quantity} spans [{lo:.4g}, {hi:.4g}] (fraction): outside [0, 1]; check the unit "
                "(percent?) and the reference of the measurement",
                stacklevel=3,
            )
    elif m.quantity == "mueller" and m.mueller_normalized and np.nanmax(np.abs(v)) > 1.05:
        warnings.warn(f"{path}: normalised Mueller elements reach {np.nanmax(np.abs(v)):.4g} (beyond ±1)", stacklevel=3)
    return m


def check_angle(path, line, value: float) -> None:
    check_range(path, line, "angle of incidence", value, 0.0, 90.0)
    if value >= 90.0:
        raise error(path, line, f"angle of incidence = {value!r} must be below 90 degrees")



# ---------------------------------------------------------------------------------------------
# the registry record: one per format module
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Head:
    """The start of a file, as the sniffing tests see it."""

    #: the file
    path: Path
    #: its first 8 KiB
    raw: bytes
    #: its first 12 non-blank lines, stripped, decoded as Latin-1 (never fails)
    lines: tuple[str, ...]

    @classmethod
    def of(cls, path) -> "Head":
        path = Path(path)
        if not path.is_file():
            raise LayerstackError(f"{path}: no such file")
        with open(path, "rb") as fh:
            raw = fh.read(8192)
        lines = tuple(ln.strip() for ln in raw.decode("latin-1").splitlines() if ln.strip())[:12]
        return cls(path, raw, lines)


@dataclass(frozen=True)
class Format:
    """A file format: what :func:`~layerstack_jax.io.sniff_format` answers, the reader
    :func:`~layerstack_jax.io.read_measurement` calls, and the test on the file's start that
    recognizes it (tests are asked in the order of ``FORMATS`` in the package ``__init__``)."""

    #: the name (``Measurement.file_format``)
    name: str
    #: ``read(path, **options) -> Measurement``
    read: Callable[..., Measurement]
    #: ``sniff(head) -> bool``: True when the file is in this format
    sniff: Callable[[Head], bool]
