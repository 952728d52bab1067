r"""The measurement object: what an instrument file says, in the library's units.

Every reader of :mod:`layerstack_jax._files.readers` (one module per file format) returns one :class:`Measurement`. It holds a
rectangular grid of angles of incidence × wavelengths and, at every grid point, the measured
quantity:

* ``"psi_delta"``: ``values`` ``(ang, 2, wl)``: ψ (``values[:, 0]``) and Δ (``values[:, 1]``),
  degrees, as the instrument reports them;
* ``"mueller"``: ``(ang, 4, 4, wl)``: Mueller matrix elements M_ij (i, j = 1..4 → indices 0..3),
  normalised by M11 where ``mueller_normalized`` (then M11 = 1);
* ``"reflectance"``: ``(ang, wl)``: specular reflectance, fraction (1 = 100 %);
* ``"transmittance"``: ``(ang, wl)``: transmittance, fraction.

The axes follow the library: angles first, wavelength last (as
:func:`~layerstack_jax.ellipsometry` returns ``psi_deg`` ``(ang, wl)`` and
:func:`~layerstack_jax.specular_mueller` returns ``(ang, 4, 4, wl)``). Grid points the file
does not contain, and the cells it leaves empty (or writes as ``NaN``, ``NA``), are NaN in ``values``
(and ``sigma``): :meth:`Measurement.valid` is the per-point mask a fit uses (``layerstack fit``
passes it as ``fitting.Dataset(mask=…)``, so missing points are left out, point by point).

Conventions ("converted at the door"): wavelengths in nm (files in Å, µm, eV or cm⁻¹ are
converted), angles in degrees, reflectance/transmittance as fractions (files in % are divided
by 100); rows of other kinds (Woollam's ``dPolE`` depolarization, ``uR`` …) are kept as written
in ``extras`` (:meth:`Measurement.depolarization` gives dPolE as a fraction). **ψ, Δ and Mueller elements are kept exactly as the
file reports them** — the convention of the instruments (Woollam, Sentech, Accurion; pyElli and
refellips read them the same way), which is the library's public convention for
:func:`~layerstack_jax.ellipsometry` and :func:`~layerstack_jax.specular_mueller`; the field
``delta_convention`` records it (``"instrument"``) and Δ is *not* wrapped into another range
(Sentech reports Δ in [0°, 360°), Woollam in (−180°, 180°] or [0°, 360°)); compare Δ modulo 360°
(:meth:`Measurement.rho` does).
"""

from __future__ import annotations

from typing import Mapping, Optional

import equinox as eqx
import numpy as np

from .._base.validate import LayerstackError

__all__ = ["Measurement", "QUANTITIES", "component_names", "measurement_from_points"]

#: The measured quantities a :class:`Measurement` can hold.
QUANTITIES = ("psi_delta", "mueller", "reflectance", "transmittance")

_COMPONENT_SHAPE = {"psi_delta": (2,), "mueller": (4, 4), "reflectance": (), "transmittance": ()}


def component_names(quantity: str) -> tuple[str, ...]:
    """Names of the components of ``quantity`` in the order of ``Measurement.values``' component axes
    (flattened, row-major): ``("psi", "delta")``, ``("M11", "M12", …, "M44")``, ``("R",)`` or ``("T",)``."""
    if quantity == "psi_delta":
        return ("psi", "delta")
    if quantity == "mueller":
        return tuple(f"M{i}{j}" for i in range(1, 5) for j in range(1, 5))
    if quantity == "reflectance":
        return ("R",)
    if quantity == "transmittance":
        return ("T",)
    raise LayerstackError(f"Measurement.quantity must be one of {QUANTITIES}, got {quantity!r}")


class Measurement(eqx.Module):
    """One measurement read from an instrument file, in the library's units (module docstring).

    A pytree (``equinox.Module``): the arrays are leaves, the descriptive strings static, so a
    measurement can travel as the data argument of a compiled fit.
    """

    #: What was measured: ``"psi_delta"``, ``"mueller"``, ``"reflectance"`` or ``"transmittance"``.
    quantity: str = eqx.field(static=True)
    #: Angles of incidence, degrees, shape ``(ang,)``, strictly increasing.
    angles_deg: np.ndarray
    #: Vacuum wavelengths, nm, shape ``(wl,)``, strictly increasing.
    wavelength_nm: np.ndarray
    #: Measured values, shape ``(ang, *component, wl)`` (table in the module docstring); NaN where
    #: the file has no value for that angle and wavelength.
    values: np.ndarray
    #: One-standard-deviation uncertainties of ``values`` (same shape, same units) where the file
    #: gives them, else ``None``.
    sigma: Optional[np.ndarray] = None
    #: Rows of other kinds the file holds next to the quantity, by the file's label (Woollam's
    #: ``dPolE`` depolarization in %, ``uR`` …): arrays ``(row, 4)`` of [wavelength_nm, second
    #: column as written (the angle for ``dPolE``), value, sigma], values as written (only the
    #: wavelength converted). Not selected by :meth:`at_angle` / :meth:`between`;
    #: :meth:`depolarization` puts ``dPolE`` on the grid.
    extras: dict = eqx.field(default_factory=dict)
    #: Sign convention of Δ and of the Mueller elements M34, M43: ``"instrument"`` (as Woollam,
    #: Sentech, Accurion instruments and pyElli/refellips report them; the library's public one).
    delta_convention: str = eqx.field(static=True, default="instrument")
    #: ``True`` when the Mueller matrix is normalised by M11 (M11 = 1), as ellipsometers report it.
    mueller_normalized: bool = eqx.field(static=True, default=False)
    #: File format the values came from (``"woollam"``, ``"sentech"``, ``"nexus"``, ``"jcamp"``,
    #: ``"csv"``, ``"accurion"``, or ``"memory"``).
    file_format: str = eqx.field(static=True, default="memory")
    #: Path of the file read, or a free description.
    source: str = eqx.field(static=True, default="")
    #: Header information and what was converted, as ``(key, value)`` string pairs in file order
    #: (sample description, instrument, original units …); :attr:`meta` gives it as a dict.
    metadata: tuple = eqx.field(static=True, default=())

    def __check_init__(self):
        if self.quantity not in QUANTITIES:
            raise LayerstackError(f"Measurement.quantity must be one of {QUANTITIES}, got {self.quantity!r}")
        ang = np.asarray(self.angles_deg)
        wl = np.asarray(self.wavelength_nm)
        if ang.ndim != 1 or wl.ndim != 1 or ang.size == 0 or wl.size == 0:
            raise LayerstackError(
                f"Measurement.angles_deg and wavelength_nm must be non-empty 1-D arrays, got shapes {ang.shape}, {wl.shape}"
            )
        if not (np.all(np.isfinite(wl)) and np.all(wl > 0) and np.all(np.diff(wl) > 0)):
            raise LayerstackError("Measurement.wavelength_nm must be finite, > 0 and strictly increasing")
        if not (np.all(np.isfinite(ang)) and np.all(ang >= 0) and np.all(ang < 90) and np.all(np.diff(ang) > 0)):
            raise LayerstackError("Measurement.angles_deg must lie in [0, 90) degrees and increase strictly")
        shape = (ang.size, *_COMPONENT_SHAPE[self.quantity], wl.size)
        if np.shape(self.values) != shape:
            raise LayerstackError(
                f"Measurement.values for quantity {self.quantity!r} must have shape (ang, *component, wl) = {shape}, "
                f"got {np.shape(self.values)}"
            )
        if self.sigma is not None and np.shape(self.sigma) != shape:
            raise LayerstackError(f"Measurement.sigma must have the shape of values {shape}, got {np.shape(self.sigma)}")
        for key, x in self.extras.items():
            if np.ndim(x) != 2 or np.shape(x)[1] != 4:
                raise LayerstackError(f"Measurement.extras[{key!r}] must have shape (row, 4), got {np.shape(x)}")

    # ------------------------------------------------------------------ views
    @property
    def meta(self) -> dict[str, str]:
        """``metadata`` as a dict (a later key wins)."""
        return dict(self.metadata)

    @property
    def psi_deg(self) -> np.ndarray:
        """ψ in degrees, ``(ang, wl)`` (``quantity == "psi_delta"`` only)."""
        self._require("psi_delta", "psi_deg")
        return self.values[:, 0]

    @property
    def delta_deg(self) -> np.ndarray:
        """Δ in degrees as the file reports it (instrument convention, range not changed), ``(ang, wl)``."""
        self._require("psi_delta", "delta_deg")
        return self.values[:, 1]

    def rho(self) -> np.ndarray:
        r""":math:`\rho = r_p/r_s = \tan\psi\, e^{-i\Delta}` in the library's exp(−iωt), n + ik
        physics — the same number as ``layerstack_jax.ellipsometry(...).rho`` for the same ψ, Δ
        (Δ as instruments report it); complex ``(ang, wl)``, free of Δ's 360° ambiguity."""
        self._require("psi_delta", "rho()")
        psi, delta = np.deg2rad(self.values[:, 0]), np.deg2rad(self.values[:, 1])
        return np.tan(psi) * np.exp(-1j * delta)

    def depolarization(self, *, tolerance_deg: float = 1e-6) -> np.ndarray:
        """Depolarization as a fraction on the grid, ``(ang, wl)``, from the file's ``dPolE`` rows
        (Woollam writes it in %); NaN where no ``dPolE`` row has the grid point's wavelength and angle."""
        out = np.full((np.size(self.angles_deg), np.size(self.wavelength_nm)), np.nan)
        rows = self.extras.get("dPolE")
        if rows is None:
            return out
        rows = np.asarray(rows)
        ia = np.abs(rows[:, 1][:, None] - np.asarray(self.angles_deg)[None, :]).argmin(axis=1)
        iw = np.abs(rows[:, 0][:, None] - np.asarray(self.wavelength_nm)[None, :]).argmin(axis=1)
        ok = (np.abs(np.asarray(self.angles_deg)[ia] - rows[:, 1]) <= tolerance_deg) & (
            np.abs(np.asarray(self.wavelength_nm)[iw] - rows[:, 0]) <= 1e-6 * rows[:, 0]
        )
        out[ia[ok], iw[ok]] = rows[ok, 2] / 100.0
        return out

    def valid(self) -> np.ndarray:
        """Boolean ``(ang, wl)``: True where the file gives every component of the quantity."""
        v = np.asarray(self.values)
        comp_axes = tuple(range(1, v.ndim - 1))
        return np.all(np.isfinite(v), axis=comp_axes) if comp_axes else np.isfinite(v)

    def _require(self, quantity: str, what: str) -> None:
        if self.quantity != quantity:
            raise LayerstackError(f"Measurement.{what} needs quantity {quantity!r}, this one is {self.quantity!r}")

    # ------------------------------------------------------------------ selections
    def angle_index(self, angle_deg: float, *, tolerance_deg: float = 0.05) -> int:
        """Index of the angle within ``tolerance_deg`` of ``angle_deg``; error naming the angles otherwise."""
        ang = np.asarray(self.angles_deg)
        i = int(np.argmin(np.abs(ang - angle_deg)))
        if abs(ang[i] - angle_deg) > tolerance_deg:
            raise LayerstackError(
                f"angle_deg {angle_deg!r}: the measurement ({self.source or 'in memory'}) has angles "
                f"{', '.join(f'{a:g}' for a in ang)} degrees"
            )
        return i

    def at_angle(self, angle_deg: float, *, tolerance_deg: float = 0.05) -> "Measurement":
        """The measurement at one angle of incidence (``ang`` axis of length 1 kept)."""
        i = self.angle_index(angle_deg, tolerance_deg=tolerance_deg)
        return self._take(np.array([i]), slice(None))

    def between(self, lo_nm: float, hi_nm: float) -> "Measurement":
        """The wavelengths in ``[lo_nm, hi_nm]`` (error if none)."""
        wl = np.asarray(self.wavelength_nm)
        keep = np.flatnonzero((wl >= lo_nm) & (wl <= hi_nm))
        if keep.size == 0:
            raise LayerstackError(
                f"no wavelength in [{lo_nm}, {hi_nm}] nm: the measurement spans {wl[0]:g}–{wl[-1]:g} nm"
            )
        return self._take(slice(None), keep)

    def _take(self, ang_sel, wl_sel) -> "Measurement":
        def take(x):
            if x is None:
                return None
            x = np.asarray(x)[ang_sel]
            return x[..., wl_sel]

        return Measurement(
            quantity=self.quantity,
            angles_deg=np.asarray(self.angles_deg)[ang_sel],
            wavelength_nm=np.asarray(self.wavelength_nm)[wl_sel],
            values=take(self.values),
            sigma=take(self.sigma),
            extras=dict(self.extras),
            delta_convention=self.delta_convention,
            mueller_normalized=self.mueller_normalized,
            file_format=self.file_format,
            source=self.source,
            metadata=self.metadata,
        )

    # ------------------------------------------------------------------ conversions
    def to_arrays(self) -> dict[str, np.ndarray]:
        """Named arrays on the grid: ``wavelength_nm (wl,)``, ``angles_deg (ang,)`` and one
        ``(ang, wl)`` array per component (``psi``/``delta``, ``M11``…``M44``, ``R`` or ``T``),
        with ``sigma_<name>`` where the file gives σ."""
        out = {"wavelength_nm": np.asarray(self.wavelength_nm), "angles_deg": np.asarray(self.angles_deg)}
        names = component_names(self.quantity)
        n_ang, n_wl = len(out["angles_deg"]), len(out["wavelength_nm"])
        flat = np.asarray(self.values).reshape(n_ang, len(names), n_wl)
        sig = None if self.sigma is None else np.asarray(self.sigma).reshape(n_ang, len(names), n_wl)
        for k, name in enumerate(names):
            out[name] = flat[:, k]
            if sig is not None:
                out[f"sigma_{name}"] = sig[:, k]
        return out

    def to_points(self) -> dict[str, np.ndarray]:
        """The valid grid points as flat columns (long format, the form of the measurement CSV):
        ``angle_deg``, ``wavelength_nm`` and the :meth:`to_arrays` components, each ``(point,)``,
        angle-major then wavelength order."""
        arrays = self.to_arrays()
        ok = self.valid()
        ang_grid, wl_grid = np.meshgrid(arrays.pop("angles_deg"), arrays.pop("wavelength_nm"), indexing="ij")
        out = {"angle_deg": ang_grid[ok], "wavelength_nm": wl_grid[ok]}
        out.update({k: v[ok] for k, v in arrays.items()})
        return out

    def equals(self, other: "Measurement", *, rtol: float = 0.0) -> bool:
        """True when every field agrees (arrays equal with NaN == NaN, to ``rtol`` if given)."""
        if not isinstance(other, Measurement):
            return False
        statics = ("quantity", "delta_convention", "mueller_normalized", "file_format", "source", "metadata")
        if any(getattr(self, s) != getattr(other, s) for s in statics):
            return False

        def same(a, b):
            if a is None or b is None:
                return a is None and b is None
            a, b = np.asarray(a), np.asarray(b)
            return a.shape == b.shape and bool(np.allclose(a, b, rtol=rtol, atol=0.0, equal_nan=True))

        fields = ("angles_deg", "wavelength_nm", "values", "sigma")
        if not all(same(getattr(self, f), getattr(other, f)) for f in fields):
            return False
        if set(self.extras) != set(other.extras):
            return False
        return all(same(self.extras[k], other.extras[k]) for k in self.extras)


def measurement_from_points(
    quantity: str,
    angle_deg,
    wavelength_nm,
    components: Mapping[str, np.ndarray],
    *,
    sigma: Optional[Mapping[str, np.ndarray]] = None,
    extras: Optional[Mapping[str, np.ndarray]] = None,
    where: str = "",
    **fields,
) -> Measurement:
    """Build a :class:`Measurement` from flat points (one entry per row of a file).

    ``angle_deg``, ``wavelength_nm`` and each array of ``components`` (keys of
    :func:`component_names`) are ``(point,)``. Points are placed on the grid of the unique angles
    and wavelengths (rounded to 1e-9 to merge the same number written twice); a point given twice
    is an error naming ``where``. ``extras``: label → ``(row, 4)`` arrays, stored as given.
    """
    names = component_names(quantity)
    ang_raw = np.asarray(angle_deg, dtype=float)
    wl_raw = np.asarray(wavelength_nm, dtype=float)
    ang = np.round(ang_raw, 9)  # keys: merge the same number written twice
    wl = np.round(wl_raw, 9)
    angle_keys, a_first = np.unique(ang, return_index=True)
    wl_keys, w_first = np.unique(wl, return_index=True)
    if angle_keys.size == 0 or wl_keys.size == 0:
        raise LayerstackError(f"{where}: no data points")
    angles, wls = ang_raw[a_first], wl_raw[w_first]  # the grid keeps the values as given

    def grid(a_pts, w_pts, vals, what):
        a_pts = np.round(np.asarray(a_pts, dtype=float), 9)
        w_pts = np.round(np.asarray(w_pts, dtype=float), 9)
        ia = np.searchsorted(angle_keys, a_pts)
        iw = np.searchsorted(wl_keys, w_pts)
        ok = (ia < angles.size) & (iw < wls.size)
        ok &= (angle_keys[np.minimum(ia, angles.size - 1)] == a_pts) & (wl_keys[np.minimum(iw, wls.size - 1)] == w_pts)
        out = np.full((angles.size, wls.size), np.nan)
        ia, iw, vals = ia[ok], iw[ok], np.asarray(vals, dtype=float)[ok]
        flat = ia * wls.size + iw
        uniq, first = np.unique(flat, return_index=True)
        if uniq.size != flat.size:
            dup = np.setdiff1d(np.arange(flat.size), first)[0]
            raise LayerstackError(
                f"{where}: {what} given twice for angle {angles[ia[dup]]:g} deg and wavelength {wls[iw[dup]]:g} nm"
            )
        out[ia, iw] = vals
        return out

    comp = np.stack([grid(ang, wl, components[n], n) for n in names], axis=1)
    shape = (angles.size, *_COMPONENT_SHAPE[quantity], wls.size)
    values = comp.reshape(shape)
    sig = None
    if sigma is not None and all(sigma.get(n) is not None for n in names):
        sig = np.stack([grid(ang, wl, sigma[n], "sigma_" + n) for n in names], axis=1).reshape(shape)
    ext = {key: np.asarray(v, dtype=float).reshape(-1, 4) for key, v in (extras or {}).items()}
    return Measurement(
        quantity=quantity,
        angles_deg=angles,
        wavelength_nm=wls,
        values=values,
        sigma=sig,
        extras=ext,
        **fields,
    )
