r"""Ellipsometry of coherent stacks: ψ and Δ as ellipsometers report them.

An ellipsometer measures the change of polarization state on specular reflection, i.e. the
ratio of the complex amplitude reflection coefficients of the stack for p and s light,

.. math::
    \rho(\lambda, \theta_0) = \frac{r_p}{r_s} = \tan\psi\; e^{-i\Delta},

with :math:`r_s, r_p` the composite amplitudes :math:`\gamma` of the Rouard recursion
(Hirayama et al. eqs. 1–4; :func:`layerstack_jax._coherent.packet_amplitudes`).

Conventions (the package's physics, see :mod:`layerstack_jax._fresnel`)
-----------------------------------------------------------------------
* Time dependence :math:`e^{-i\omega t}`, index :math:`n + ik` with :math:`k \ge 0`.
* Amplitudes as in Born & Wolf and ``tmm``: :math:`r_s = (q_i - q_f)/(q_i + q_f)`,
  :math:`r_p = (n_f^2 q_i - n_i^2 q_f)/(n_f^2 q_i + n_i^2 q_f)`; at normal incidence
  :math:`r_p = -r_s`.

The reported Δ: the instruments' convention
--------------------------------------------
Ellipsometers (J. A. Woollam, Sentech SpectraRay, Accurion) and the peer codes pyElli and
refellips report :math:`\Delta = -\arg(r_p/r_s)` in the physics above — equivalently
:math:`\tan\psi\, e^{i\Delta} = r_p/r_s` written with :math:`e^{+i\omega t}` and
:math:`n - ik` (the "Nebraska" convention of Azzam & Bashara and Fujiwara). So does this
module:

* :math:`\Delta = -\arg(r_p/r_s)`, reported in (−180°, 180°] (a real negative :math:`\rho`
  gives +180°, never −180°); add 360° to negative values for an instrument's [0°, 360°) file.
  :math:`\psi = \arctan|r_p/r_s| \in [0°, 90°]`.
* Over a bare absorbing substrate :math:`\Delta \in (0°, 180°)`: silicon with its 2 nm native
  oxide at 70° reads :math:`\Delta \approx 110°`–174° from 250 to 800 nm in a Woollam RC2 file
  (tests/test_ellipsometry.py matches it to < 1° rms; the opposite sign misses it by > 40° rms).
* Lossless dielectric substrate: :math:`\Delta = 180°` below Brewster's angle, 0° above,
  :math:`\psi = 45°` at normal incidence, 0° at Brewster's angle (Fujiwara's textbook values).
* ``tmm.ellips`` returns the same ψ and :math:`\Delta_\text{tmm} = \arg(-r_p/r_s)`, so
  :math:`\Delta = 180° - \Delta_\text{tmm}` (wrapped into (−180°, 180°]).
* :attr:`Ellipsometry.rho` stays the physical ratio :math:`r_p/r_s = \tan\psi\,e^{-i\Delta}`
  (pyElli's ``Result.rho`` is the same number); the instruments' complex ratio
  :math:`\tan\psi\,e^{i\Delta}` is its complex conjugate.

Fitting ellipsometric data: three residual kinds
------------------------------------------------
:class:`Ellipsometric` is the measurement geometry of a fit (``fitting.Dataset``); its
``quantity`` chooses what is compared with the data, and :meth:`Ellipsometric.residual` how:

* ``'psi'``, ``'delta'`` (degrees): ψ/Δ. The Δ residual is the model−data difference wrapped
  into (−180°, 180°] (:func:`wrap_degrees`): a Δ that crosses ±180° within a spectrum, or
  data reported in [0°, 360°), is compared on the circle, not across a 360° jump.
* ``'N'``, ``'C'``, ``'S'``: the wrap-free combinations :math:`N = \cos 2\psi`,
  :math:`C = \sin 2\psi\cos\Delta`, :math:`S = \sin 2\psi \sin\Delta` (what rotating-compensator
  instruments measure, with the same Δ), smooth everywhere.
* ``'rho_re'``, ``'rho_im'``: real and imaginary parts of
  :math:`\rho = r_p/r_s = \tan\psi\,e^{-i\Delta}` — the library's one ρ convention (the same
  number as :attr:`Ellipsometry.rho`, ``Measurement.rho()`` and pyElli's ``Result.rho``), so
  :math:`\mathrm{Re}\,\rho = \tan\psi\cos\Delta`, :math:`\mathrm{Im}\,\rho = -\tan\psi\sin\Delta`
  with the instruments' Δ. Wrap-free as well; large where ψ → 90°.

Δ, S and Im ρ change sign with Δ (:attr:`Ellipsometric.odd_in_delta`): a file written in the
opposite Δ convention fits far better mirrored, which ``fitting`` reports. The normalized
Mueller matrix of the reflection is
:math:`[[1, -N, 0, 0], [-N, 1, 0, 0], [0, 0, C, S], [0, 0, -S, C]]`, as measured
(:mod:`layerstack_jax._polarimetry`).
"""

from __future__ import annotations

from typing import ClassVar, NamedTuple

import jax.numpy as jnp

import equinox as eqx

from ._coherent import packet_amplitudes
from ._geometry import Geometry
from ._custom_types import Array, Complex, Float, RealLike
from ._illumination import snell_invariant
from ._numerics import safe_abs, safe_atan2
from ._stack import ResolvedStack, Stack, resolve
from ._validate import LayerstackError, check_angle_deg, is_concrete

__all__ = ["Ellipsometry", "ellipsometry", "reflection_amplitudes", "psi_delta", "wrap_degrees"]

#: the quantities an :class:`Ellipsometric` geometry reads (one per dataset)
QUANTITIES = ("psi", "delta", "N", "C", "S", "rho_re", "rho_im")


class Ellipsometry(NamedTuple):
    r"""Ellipsometric response, every field shaped ``(*angle, wl)``.

    Attributes:
        psi_deg: :math:`\psi` in degrees, in [0, 90].
        delta_deg: :math:`\Delta = -\arg(r_p/r_s)` in degrees, in (−180, 180]: the sign
            ellipsometers report (module docstring).
        rho: complex :math:`\rho = r_p/r_s = \tan\psi\, e^{-i\Delta}` (physics convention
            :math:`e^{-i\omega t}`, as pyElli's ``Result.rho``).
    """

    psi_deg: Float[Array, "*angle wl"]
    delta_deg: Float[Array, "*angle wl"]
    rho: Complex[Array, "*angle wl"]

    @property
    def N(self):
        r""":math:`\cos 2\psi` (smooth, for fitting)."""
        return jnp.cos(2 * jnp.deg2rad(self.psi_deg))

    @property
    def C(self):
        r""":math:`\sin 2\psi \cos\Delta` (smooth, for fitting)."""
        return jnp.sin(2 * jnp.deg2rad(self.psi_deg)) * jnp.cos(jnp.deg2rad(self.delta_deg))

    @property
    def S(self):
        r""":math:`\sin 2\psi \sin\Delta` (smooth, for fitting)."""
        return jnp.sin(2 * jnp.deg2rad(self.psi_deg)) * jnp.sin(jnp.deg2rad(self.delta_deg))


def wrap_degrees(angle_deg):
    r"""An angle difference in degrees wrapped into (−180°, 180°]: ``180 - ((180 - x) mod 360)``.

    ``angle_deg``: any shape (degrees); returns the same shape. Used for Δ residuals
    (:meth:`Ellipsometric.residual`): 350° − (−5°) = 355° is −5°, not 355°.

    Differentiable: away from the odd multiples of 180° it is :math:`x - 360°k` with a locally
    constant integer k, so its derivative is exactly 1 (JAX's ``remainder`` has derivative 1 in
    its first argument) — no trigonometry, no division, no NaN. At ±180° the wrapped value jumps
    from 180° to −180°, but the least-squares cost (its square) is continuous there: the
    residual of a point whose model and data are opposite on the circle is 180° either way.
    """
    return 180.0 - jnp.remainder(180.0 - jnp.asarray(angle_deg), 360.0)


def psi_delta(r_s, r_p):
    r""":math:`(\psi, \Delta)` in radians from the amplitude reflection coefficients.

    :math:`\psi = \operatorname{atan2}(|r_p|, |r_s|)`, :math:`\Delta = \arg(r_s \bar r_p)
    = -\arg(r_p/r_s)` (the instruments' sign, module docstring); both are NaN-free with
    finite gradients also at Brewster's angle (:math:`r_p = 0`).

    ``r_s``, ``r_p``: complex amplitude coefficients (dimensionless, convention
    :math:`e^{-i\omega t}`), broadcast against each other to ``(*B)`` (e.g. ``(*angle, wl)``).
    Returns ``(psi, delta)``, each ``(*B)``, in radians: ψ in [0, π/2], Δ in (−π, π].
    """
    psi = safe_atan2(safe_abs(r_p), safe_abs(r_s))
    c = r_s * jnp.conj(r_p)  # arg = -arg(r_p / r_s): the sign ellipsometers report
    delta = safe_atan2(jnp.imag(c), jnp.real(c))
    # atan2(-0.0, x < 0) = -pi: a real negative rho must give +pi (range (-pi, pi]).
    delta = jnp.where(delta <= -jnp.pi, jnp.pi, delta)
    return psi, delta


def _check_coherent(stack: Stack) -> None:
    for i, layer in enumerate(stack.layers):
        if not layer.coherent:
            raise LayerstackError(
                f"layers[{i}] ({layer.name or 'unnamed'}): ellipsometry needs a fully coherent stack; "
                "a thick incoherent layer depolarizes (use layerstack_jax.specular_mueller)"
            )


def _amplitudes_resolved(rs: ResolvedStack, angle_rad):
    s = snell_invariant(rs.n[0], angle_rad)
    gamma, _, _ = packet_amplitudes(rs.n, rs.d, s, rs.wavelength)
    shape = jnp.broadcast_shapes(gamma.shape[1:], jnp.shape(s)[:-1] + (rs.wavelength.shape[-1],))
    return jnp.broadcast_to(gamma[0], shape), jnp.broadcast_to(gamma[1], shape)


def reflection_amplitudes(stack: Stack, wavelength_nm, angle_deg: RealLike):
    r"""Complex amplitude reflection coefficients :math:`(r_s, r_p)` of a coherent stack.

    Args:
        stack: ambient · coherent films · exit (a :class:`~layerstack_jax.Substrate`, or the
            binder of a :class:`~layerstack_jax.LambertianBackground`: its specular face).
        wavelength_nm: ``(wl,)`` vacuum wavelengths, nm.
        angle_deg: angle of incidence in the ambient, degrees in [0, 90); any shape ``(*angle)``.

    Returns:
        ``(r_s, r_p)``, complex arrays shaped ``(*angle, wl)`` (module conventions).
    """
    _check_coherent(stack)
    check_angle_deg("angle_deg", angle_deg)
    rs = resolve(stack, wavelength_nm)
    return _amplitudes_resolved(rs, jnp.deg2rad(angle_deg))


def ellipsometry(stack: Stack, wavelength_nm, angle_deg: RealLike) -> Ellipsometry:
    r"""Ellipsometric angles :math:`\psi, \Delta` and ratio :math:`\rho = r_p/r_s` of a coherent stack.

    A pure, jit-, vmap- and grad-compatible function of the stack's leaves (thicknesses, n, k):
    differentiate ``psi_deg``, ``delta_deg`` or (better, wrap-free) ``rho``, ``N``, ``C``, ``S``
    with respect to any of them.

    Args:
        stack: ambient (real index) · coherent films · exit medium.
        wavelength_nm: ``(wl,)`` vacuum wavelengths, nm.
        angle_deg: angle of incidence, degrees in [0, 90); scalar or any shape ``(*angle)``.

    Returns:
        :class:`Ellipsometry` with fields shaped ``(*angle, wl)``; Δ with the sign and range
        ellipsometers report (Woollam, Sentech, Accurion, pyElli, refellips); relation to
        ``tmm.ellips`` in the module docstring.
    """
    r_s, r_p = reflection_amplitudes(stack, wavelength_nm, angle_deg)
    psi, delta = psi_delta(r_s, r_p)
    return Ellipsometry(jnp.rad2deg(psi), jnp.rad2deg(delta), r_p / r_s)


class Ellipsometric(Geometry):
    """An ellipsometer's reading at ``angle_deg`` (degrees), as a measurement geometry: lets
    ψ/Δ spectra be fitted (``fitting.Dataset(Ellipsometric(70, "psi"), data)``).

    ``quantity`` (one per dataset; "Fitting ellipsometric data" in the module docstring):

    * ``'psi'`` or ``'delta'``: degrees, conventions of :func:`ellipsometry`; the Δ residual of
      a fit is wrapped into (−180°, 180°] (:meth:`residual`), so Δ data may cross ±180° or be
      reported in [0°, 360°);
    * ``'N'`` = cos 2ψ, ``'C'`` = sin 2ψ cos Δ, ``'S'`` = sin 2ψ sin Δ (dimensionless, wrap-free);
    * ``'rho_re'``, ``'rho_im'``: Re and Im of ρ = r_p/r_s = tan ψ e^{−iΔ} (dimensionless,
      wrap-free; the convention of :attr:`Ellipsometry.rho` and ``Measurement.rho()``).

    ``angle_deg``: scalar or array ``(*angle)`` of incidence angles in degrees; :meth:`measure`
    returns ``(*angle, wl)``.
    """

    angle_deg: object = 70.0
    quantity: str = eqx.field(static=True, default="psi")

    def __check_init__(self):
        if self.quantity not in QUANTITIES:
            raise LayerstackError(
                f"Ellipsometric.quantity must be one of {', '.join(map(repr, QUANTITIES))}, got {self.quantity!r}"
            )
        check_angle_deg("Ellipsometric.angle_deg", self.angle_deg)

    spelling: ClassVar[str] = "ellipsometry:ANGLE:psi|delta|N|C|S|rho_re|rho_im"
    signed: ClassVar[bool] = True  # Δ, C, S, Re ρ, Im ρ may be negative
    reads_diffuse_light: ClassVar[bool] = False
    reading_is_fraction: ClassVar[bool] = False

    def measure(self, stack: Stack, wavelength_nm, *, nodes: int = 0, optics=None) -> Float[Array, "*angle wl"]:
        """The quantity read for ``stack`` on ``wavelength_nm`` (nm); ``nodes`` and ``optics``
        are not used (an ellipsometer reads amplitudes, not the cached intensities)."""
        e = ellipsometry(stack, wavelength_nm, self.angle_deg)
        if self.quantity == "rho_re":
            return jnp.real(e.rho)
        if self.quantity == "rho_im":
            return jnp.imag(e.rho)
        return {"psi": e.psi_deg, "delta": e.delta_deg, "N": e.N, "C": e.C, "S": e.S}[self.quantity]

    def residual(self, model, data):
        """Model − data; for ``'delta'`` wrapped into (−180°, 180°] by :func:`wrap_degrees`
        (derivative 1 in ``model``, NaN-free), so that Δ = 179° against data −179° is a 2° miss."""
        if self.quantity == "delta":
            return wrap_degrees(model - data)
        return model - data

    @property
    def odd_in_delta(self) -> bool:
        """True when the reading changes sign with Δ (Δ, S, Im ρ): data written in the opposite
        Δ convention are these readings negated (ψ, N, C, Re ρ are even in Δ)."""
        return self.quantity in ("delta", "S", "rho_im")

    # the Geometry interface: an ellipsometer needs no Optics (it overrides measure)
    def optics(self, rs, background, nodes):
        return None

    def read(self, rs, optics, background):
        raise LayerstackError("Ellipsometric reads through measure(), not through Optics")

    @property
    def label(self) -> str:
        a = self.angle_deg
        text = f"{float(a):g}" if is_concrete(a) and jnp.ndim(a) == 0 else "array"
        return f"ellipsometry:{text}:{self.quantity}"

    @property
    def quantity_label(self) -> str:
        return {"psi": "psi (degrees)", "delta": "Delta (degrees)", "N": "N = cos 2psi", "C": "C = sin 2psi cos Delta",
                "S": "S = sin 2psi sin Delta", "rho_re": "Re rho = tan psi cos Delta",
                "rho_im": "Im rho = -tan psi sin Delta"}[self.quantity]

    @classmethod
    def parse(cls, text: str):
        """``ellipsometry:ANGLE:QUANTITY`` (QUANTITY psi, delta, N, C, S, rho_re or rho_im; default
        psi; case-insensitive)."""
        if not text.startswith("ellipsometry"):
            return None
        parts = text.split(":")
        if not 2 <= len(parts) <= 3:
            raise ValueError(text)
        q = parts[2] if len(parts) > 2 else "psi"
        q = q.lower()
        q = q if q in ("psi", "delta", "rho_re", "rho_im") else q.upper()
        return cls(float(parts[1]), q)
