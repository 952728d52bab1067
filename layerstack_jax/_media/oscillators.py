r"""Oscillator dispersion models under the names of ellipsometry software.

Each model is a :class:`~layerstack_jax._media.materials.Material`: an equinox module whose numeric
fields are JAX leaves (fittable, differentiable), called with wavelengths in nm and returning
the complex index :math:`\tilde n = \sqrt{\varepsilon} = n + ik` (:math:`k \ge 0`; time
dependence :math:`e^{-i\omega t}`, :math:`\varepsilon = \varepsilon_1 + i\varepsilon_2`,
:math:`\varepsilon_2 \ge 0` for absorption). The root of :math:`\sqrt{\varepsilon}` is the
principal one, which has :math:`k \ge 0` whenever :math:`\varepsilon_2 \ge 0`.

Photon energy :math:`E = hc/\lambda`, with :math:`hc = 1239.841984332\ \text{eV nm}` (exact
in the 2019 SI). Energies in eV. Coefficients that are arrays of shape ``(osc,)`` describe
several oscillators summed; they broadcast against the wavelength grid ``(wl,)`` through a
trailing axis, so a model evaluated on ``(wl,)`` returns ``(wl,)``.

Models (with the parameter names of pyElli, which the tests compare against):

* :class:`Lorentz` — :math:`\varepsilon = \varepsilon_\infty + \sum_j A_j/(E_j^2 - E^2 - i\Gamma_j E)`.
* :class:`Drude` — :math:`\varepsilon = \varepsilon_\infty - E_p^2/(E^2 + i\Gamma E)` (free
  carriers; :math:`E_p = \hbar\omega_p`).
* :class:`TaucLorentz` — Jellison & Modine, Appl. Phys. Lett. 69, 371 (1996) and erratum
  69, 2137: ε₂ of eq. (4), ε₁ the closed-form Kramers–Kronig transform (their eq. in the
  erratum), amorphous semiconductors and dielectrics.
* :class:`CodyLorentz` — Ferlauto et al., J. Appl. Phys. 92, 2424 (2002), eqs. (3)–(4):
  Cody absorption onset, Lorentz peak, Urbach tail below :math:`E_t`; ε₁ by a Kramers–Kronig
  quadrature done here in jnp (Gauss–Legendre, differentiable).
* :class:`CauchyUrbach` — Cauchy index (λ in µm, as :class:`~layerstack_jax.Cauchy`) with an
  Urbach absorption tail :math:`k = k_0 \exp((E - E_b)/E_u)`.
* Sellmeier: :class:`~layerstack_jax.Sellmeier` (in :mod:`layerstack_jax._media.materials`).
"""

from __future__ import annotations

import warnings

import jax.numpy as jnp
import numpy as np

from .._base.custom_types import Coefficients, RealLike
from .._base.numerics import as_complex, complex_from
from .._base.validate import LayerstackError, LayerstackWarning, check_finite, check_nonnegative, is_concrete
from .materials import Material

__all__ = ["HC_EV_NM", "photon_energy", "Lorentz", "Drude", "TaucLorentz", "CodyLorentz", "CauchyUrbach"]

#: h c / e in eV nm (exact since the 2019 SI: h and e are defined constants).
HC_EV_NM = 1239.8419843320026


def photon_energy(wavelength_nm):
    """Photon energy in eV of vacuum wavelengths in nm (any shape)."""
    return HC_EV_NM / jnp.asarray(wavelength_nm)


def _osc(x):
    """Coefficient array ``(osc,)`` with a trailing axis to broadcast against ``(wl,)``."""
    return jnp.atleast_1d(jnp.asarray(x))[..., None]


def _index_from_permittivity(eps1, eps2):
    r""":math:`\sqrt{\varepsilon_1 + i\varepsilon_2}`, principal root (k ≥ 0 for ε₂ ≥ 0).
    ``+ 0.0`` turns a −0.0 imaginary part into +0.0 so that a lossless negative ε₁ gives
    +ik, not −ik."""
    return jnp.sqrt(complex_from(eps1, eps2 + 0.0))


def _safe_xlogx2(x):
    r""":math:`x^2 \ln|x|`, 0 at x = 0 with a finite (zero) gradient (double where)."""
    zero = x == 0
    xs = jnp.where(zero, 1.0, x)
    return jnp.where(zero, 0.0, xs**2 * jnp.log(jnp.abs(xs)))


def _check_oscillators(name, **fields):
    for field, v in fields.items():
        check_finite(f"{name}.{field}", v)
    shapes = {f: np.shape(v) for f, v in fields.items() if is_concrete(v)}
    if len(set(shapes.values())) > 1:
        raise LayerstackError(f"{name}: oscillator fields {sorted(shapes)} must have the same shape, got {shapes}")


class Lorentz(Material):
    r"""Lorentz oscillators: :math:`\varepsilon(E) = \varepsilon_\infty + \sum_j
    A_j / (E_j^2 - E^2 - i\Gamma_j E)` (pyElli ``LorentzEnergy`` plus ``EpsilonInf``).

    Attributes:
        A: amplitudes in eV², shape ``(osc,)`` or scalar.
        E0: resonance energies in eV, same shape.
        gamma: broadenings Γ in eV (≥ 0), same shape.
        eps_inf: ε∞, dimensionless (default 1).

    Called with wavelengths in nm ``(wl,)``, returns n + ik ``(wl,)``.
    """

    A: Coefficients
    E0: Coefficients
    gamma: Coefficients
    eps_inf: RealLike = 1.0

    def __check_init__(self):
        _check_oscillators("Lorentz", A=self.A, E0=self.E0, gamma=self.gamma)
        check_nonnegative("Lorentz.gamma", self.gamma, "(broadening) must be >= 0")

    def permittivity(self, wavelength_nm):
        """Complex ε on the grid (nm) ``(wl,)``."""
        E = photon_energy(wavelength_nm)
        denominator = complex_from(_osc(self.E0) ** 2 - E**2, 0.0 - _osc(self.gamma) * E)
        terms = as_complex(_osc(self.A), denominator) / denominator
        return as_complex(self.eps_inf, terms) + jnp.sum(terms, axis=0)

    def __call__(self, wavelength_nm):
        eps = self.permittivity(wavelength_nm)
        return _index_from_permittivity(jnp.real(eps), jnp.imag(eps))


class Drude(Material):
    r"""Drude free-carrier term: :math:`\varepsilon(E) = \varepsilon_\infty - E_p^2/(E^2 + i\Gamma E)`.

    (pyElli's ``DrudeEnergy`` writes :math:`A/(E^2 - i\Gamma E)`; the same ε is
    ``DrudeEnergy(A=-Ep**2, gamma=-Gamma)`` there.)

    Attributes:
        Ep: plasma energy :math:`\hbar\omega_p` in eV.
        gamma: collision rate Γ = ħ/τ in eV (≥ 0).
        eps_inf: ε∞, dimensionless (default 1).

    Called with wavelengths in nm ``(wl,)``, returns n + ik ``(wl,)``.
    """

    Ep: RealLike
    gamma: RealLike
    eps_inf: RealLike = 1.0

    def __check_init__(self):
        check_finite("Drude.Ep", self.Ep)
        check_nonnegative("Drude.gamma", self.gamma, "(collision rate) must be >= 0")

    def permittivity(self, wavelength_nm):
        """Complex ε on the grid (nm) ``(wl,)``."""
        E = photon_energy(wavelength_nm)
        denominator = complex_from(E**2, jnp.asarray(self.gamma) * E)
        return as_complex(self.eps_inf, denominator) - as_complex(jnp.asarray(self.Ep) ** 2, denominator) / denominator

    def __call__(self, wavelength_nm):
        eps = self.permittivity(wavelength_nm)
        return _index_from_permittivity(jnp.real(eps), jnp.imag(eps))


def tauc_lorentz_eps2(E, Eg, A, E0, C):
    r"""Tauc–Lorentz :math:`\varepsilon_2` (Jellison & Modine 1996, eq. 4): zero below
    :math:`E_g`, :math:`A E_0 C (E-E_g)^2 / [((E^2-E_0^2)^2 + C^2E^2) E]` above. Energies in
    eV; E ``(wl,)``, the rest ``(osc, 1)`` or scalars; returns ``(osc, wl)``."""
    above = E > Eg
    x = jnp.where(above, E - Eg, 0.0)
    return A * E0 * C * x**2 / (((E**2 - E0**2) ** 2 + C**2 * E**2) * E)


def tauc_lorentz_eps1(E, Eg, A, E0, C):
    r"""Tauc–Lorentz :math:`\varepsilon_1 - \varepsilon_\infty`: the closed-form Kramers–Kronig
    transform of :func:`tauc_lorentz_eps2` (Jellison & Modine 1996, erratum), with

    :math:`a_{ln} = (E_g^2 - E_0^2)E^2 + E_g^2C^2 - E_0^2(E_0^2 + 3E_g^2)`,
    :math:`a_{atan} = (E^2 - E_0^2)(E_0^2 + E_g^2) + E_g^2C^2`,
    :math:`\alpha = \sqrt{4E_0^2 - C^2}`, :math:`\gamma^2 = E_0^2 - C^2/2`,
    :math:`\zeta^4 = (E^2 - \gamma^2)^2 + \alpha^2C^2/4`.

    The paper's two :math:`\ln|E - E_g|` terms are combined here into
    :math:`-(E - E_g)^2 \ln|E - E_g| + (E + E_g)^2 \ln(E + E_g) - E E_g \ln((E_0^2-E_g^2)^2 + E_g^2C^2)`
    (times :math:`A E_0 C/(\pi\zeta^4 E)`), which is finite, with a finite gradient, at
    :math:`E = E_g`. Needs :math:`C < 2E_0`. Shapes as :func:`tauc_lorentz_eps2`.
    """
    alpha = jnp.sqrt(4 * E0**2 - C**2)
    gamma2 = E0**2 - C**2 / 2
    a_ln = (Eg**2 - E0**2) * E**2 + Eg**2 * C**2 - E0**2 * (E0**2 + 3 * Eg**2)
    a_atan = (E**2 - E0**2) * (E0**2 + Eg**2) + Eg**2 * C**2
    zeta4 = (E**2 - gamma2) ** 2 + alpha**2 * C**2 / 4
    t1 = A * C * a_ln / (2 * jnp.pi * zeta4 * alpha * E0) * jnp.log(
        (E0**2 + Eg**2 + alpha * Eg) / (E0**2 + Eg**2 - alpha * Eg)
    )
    t2 = -A * a_atan / (jnp.pi * zeta4 * E0) * (
        jnp.pi - jnp.arctan((2 * Eg + alpha) / C) + jnp.arctan((alpha - 2 * Eg) / C)
    )
    t3 = 2 * A * E0 * Eg / (jnp.pi * zeta4 * alpha) * (E**2 - gamma2) * (
        jnp.pi + 2 * jnp.arctan(2 * (gamma2 - Eg**2) / (alpha * C))
    )
    t45 = A * E0 * C / (jnp.pi * zeta4 * E) * (
        -_safe_xlogx2(E - Eg)
        + (E + Eg) ** 2 * jnp.log(E + Eg)
        - E * Eg * jnp.log((E0**2 - Eg**2) ** 2 + Eg**2 * C**2)
    )
    return t1 + t2 + t3 + t45


class TaucLorentz(Material):
    r"""Tauc–Lorentz dispersion (Jellison & Modine 1996): one band gap, one or more Lorentz
    oscillators; ε₂ and ε₁ in closed form (:func:`tauc_lorentz_eps2`, :func:`tauc_lorentz_eps1`).

    Attributes:
        Eg: Tauc band gap in eV (scalar, shared by the oscillators).
        A: amplitudes in eV, shape ``(osc,)`` or scalar.
        E0: peak energies in eV (> Eg), same shape.
        C: broadenings in eV (0 < C < 2 E0), same shape.
        eps_inf: ε∞, dimensionless (default 1).

    Called with wavelengths in nm ``(wl,)``, returns n + ik ``(wl,)``.
    """

    Eg: RealLike
    A: Coefficients
    E0: Coefficients
    C: Coefficients
    eps_inf: RealLike = 1.0

    def __check_init__(self):
        _check_oscillators("TaucLorentz", A=self.A, E0=self.E0, C=self.C)
        check_nonnegative("TaucLorentz.Eg", self.Eg, "(band gap, eV) must be >= 0")
        if is_concrete((self.C, self.E0)):
            C, E0 = np.asarray(self.C), np.asarray(self.E0)
            if np.any(C <= 0) or np.any(C >= 2 * E0):
                raise LayerstackError("TaucLorentz.C (broadening) must satisfy 0 < C < 2 E0")
        if is_concrete((self.E0, self.Eg)) and np.any(np.asarray(self.E0) <= np.asarray(self.Eg)):
            warnings.warn("TaucLorentz.E0 (peak) at or below Eg (band gap): implausible "
                          "(Jellison & Modine assume E0 > Eg)", LayerstackWarning, stacklevel=3)

    def permittivity(self, wavelength_nm):
        """Complex ε on the grid (nm) ``(wl,)``."""
        E = photon_energy(wavelength_nm)
        args = (E, self.Eg, _osc(self.A), _osc(self.E0), _osc(self.C))
        oscillators = jnp.sum(complex_from(tauc_lorentz_eps1(*args), tauc_lorentz_eps2(*args)), axis=0)
        return as_complex(self.eps_inf, oscillators) + oscillators

    def __call__(self, wavelength_nm):
        eps = self.permittivity(wavelength_nm)
        return _index_from_permittivity(jnp.real(eps), jnp.imag(eps))


def cody_lorentz_eps2(E, Eg, A, E0, gamma, Ep, Et, Eu):
    r"""Cody–Lorentz :math:`\varepsilon_2` (Ferlauto et al. 2002, eqs. 3–4), energies in eV:

    :math:`E > E_t`: :math:`G(E) L(E)`, :math:`G = (E-E_g)^2/((E-E_g)^2 + E_p^2)`,
    :math:`L = A E_0 \Gamma E/((E^2-E_0^2)^2 + \Gamma^2E^2)`;
    :math:`E \le E_t`: Urbach tail :math:`(E_t G(E_t) L(E_t)/E) \exp((E - E_t)/E_u)`.
    Continuous at :math:`E_t`. Any broadcastable shapes."""

    def G(x):
        return (x - Eg) ** 2 / ((x - Eg) ** 2 + Ep**2)

    def L(x):
        return A * E0 * gamma * x / ((x**2 - E0**2) ** 2 + gamma**2 * x**2)

    positive = E > 0
    E_safe = jnp.where(positive, E, 1.0)  # ε₂(0) = 0; double where keeps the gradient finite
    tail = jnp.where(positive, Et * G(Et) * L(Et) / E_safe * jnp.exp(jnp.minimum(E - Et, 0.0) / Eu), 0.0)
    return jnp.where(E > Et, G(E) * L(E), tail)


#: Gauss–Legendre rule on [0, 1] used by the Kramers–Kronig quadrature of CodyLorentz.
_KK_NODES = 64


def _gauss01(n):
    x, w = np.polynomial.legendre.leggauss(n)
    return (x + 1) / 2, w / 2


class CodyLorentz(Material):
    r"""Cody–Lorentz dispersion (Ferlauto et al. 2002): ε₂ of :func:`cody_lorentz_eps2`,
    :math:`\varepsilon_1 = \varepsilon_\infty + \frac{2}{\pi} P\!\int_0^\infty
    \frac{\xi\varepsilon_2(\xi)}{\xi^2 - E^2} d\xi`.

    The principal value is removed by subtracting :math:`E\varepsilon_2(E)` from the numerator
    (:math:`P\int_0^\infty d\xi/(\xi^2 - E^2) = 0`), and the regular integral is done by
    Gauss–Legendre on fixed segments split at :math:`E_t`, the evaluation energy E and the
    peak, with the tail :math:`[E_\text{hi}, \infty)` mapped by :math:`\xi = E_\text{hi}/u`
    (ε₂ falls as :math:`\xi^{-3}`). All in jnp: differentiable in every parameter.
    Accuracy: ≤ 1e-6 relative against scipy quadrature on typical parameters (tests).

    Attributes:
        Eg: band gap (eV); A: amplitude (eV); E0: Lorentz peak (eV); gamma: broadening (eV);
        Ep: Cody-to-Lorentz transition width (eV); Et: start of the Urbach tail (eV, ≥ Eg);
        Eu: Urbach energy (eV, > 0); eps_inf: ε∞ (default 1). All scalars.

    Called with wavelengths in nm ``(wl,)``, returns n + ik ``(wl,)``.
    """

    Eg: RealLike
    A: RealLike
    E0: RealLike
    gamma: RealLike
    Ep: RealLike
    Et: RealLike
    Eu: RealLike
    eps_inf: RealLike = 1.0

    def __check_init__(self):
        for f in ("Eg", "A", "E0", "gamma", "Ep", "Et", "Eu"):
            check_nonnegative(f"CodyLorentz.{f}", getattr(self, f))
        if is_concrete(self.Eu) and np.any(np.asarray(self.Eu) <= 0):
            raise LayerstackError("CodyLorentz.Eu (Urbach energy) must be > 0")
        if is_concrete((self.Et, self.Eg)) and np.any(np.asarray(self.Et) < np.asarray(self.Eg)):
            warnings.warn("CodyLorentz.Et (start of the Urbach tail) below Eg (band gap): implausible "
                          "(Ferlauto et al. take Et >= Eg)", LayerstackWarning, stacklevel=3)

    def _eps2(self, E):
        return cody_lorentz_eps2(E, self.Eg, self.A, self.E0, self.gamma, self.Ep, self.Et, self.Eu)

    def _eps1(self, E):
        """ε₁ − ε∞ by the subtracted Kramers–Kronig integral, E ``(wl,)`` → ``(wl,)``."""
        u, w = _gauss01(_KK_NODES)
        u, w = jnp.asarray(u), jnp.asarray(w)
        E = E[:, None]
        f_E = E * self._eps2(E)

        def integrand(xi):
            d = xi**2 - E**2
            close = jnp.abs(d) < 1e-300
            return jnp.where(close, 0.0, (xi * self._eps2(xi) - f_E) / jnp.where(close, 1.0, d))

        # breakpoints: 0, Urbach region (Et − 40 Eu .. Et), E, peak region, then the tail
        lo_tail = jnp.maximum(self.Et - 40.0 * self.Eu, 0.0)
        hi = jnp.maximum(4.0 * (self.E0 + self.gamma), 2.0 * E) + self.Et
        pts = jnp.sort(
            jnp.concatenate(
                [
                    jnp.broadcast_to(jnp.stack([0.0 * self.Et, lo_tail, self.Et, self.E0]), (E.shape[0], 4)),
                    E,
                    hi,
                ],
                axis=1,
            ),
            axis=1,
        )  # (wl, 6)
        a, b = pts[:, :-1, None], pts[:, 1:, None]  # (wl, 5, 1)
        xi = a + (b - a) * u  # (wl, 5, n)
        seg = jnp.sum(_on_segments(integrand, xi) * w * (b - a), axis=(1, 2))
        # tail: xi = hi / v, v in (0, 1], d xi = hi / v^2 dv
        h = hi[:, :1]
        v = u[None, :]
        xt = h / v
        tail = jnp.sum(integrand(xt) * h / v**2 * w, axis=1)
        return 2.0 / jnp.pi * (seg + tail)

    def permittivity(self, wavelength_nm):
        """Complex ε on the grid (nm) ``(wl,)``."""
        E = jnp.atleast_1d(photon_energy(wavelength_nm))
        eps = complex_from(self.eps_inf + self._eps1(E), self._eps2(E))
        return jnp.reshape(eps, jnp.shape(jnp.asarray(wavelength_nm)))

    def __call__(self, wavelength_nm):
        eps = self.permittivity(wavelength_nm)
        return _index_from_permittivity(jnp.real(eps), jnp.imag(eps))


def _on_segments(integrand, xi):
    """Evaluate ``integrand`` (written for ``(wl, n)``) on segment nodes ``(wl, seg, n)``."""
    wl, s, n = xi.shape
    return integrand(xi.reshape(wl, s * n)).reshape(wl, s, n)


class CauchyUrbach(Material):
    r"""Cauchy index with an Urbach absorption tail (the "Cauchy + Urbach" of ellipsometry
    software): :math:`n = A + B/\lambda^2 + C/\lambda^4` (λ in µm, as
    :class:`~layerstack_jax.Cauchy`), :math:`k = k_0 \exp((E - E_b)/E_u)`, E the photon
    energy in eV.

    Attributes:
        A: dimensionless; B in µm²; C in µm⁴.
        k0: extinction at the band edge (≥ 0, dimensionless).
        Eb: band-edge energy in eV.
        Eu: Urbach energy in eV (> 0).

    Called with wavelengths in nm ``(wl,)``, returns n + ik ``(wl,)``. (pyElli's
    ``CauchyUrbach`` writes n in powers of E: the same model with
    :math:`B_E = B/(hc)^2`, :math:`C_E = C/(hc)^4`, hc in eV µm.)
    """

    A: RealLike
    B: RealLike = 0.0
    C: RealLike = 0.0
    k0: RealLike = 0.0
    Eb: RealLike = 3.0
    Eu: RealLike = 0.5

    def __check_init__(self):
        check_nonnegative("CauchyUrbach.k0", self.k0)
        if is_concrete(self.Eu) and np.any(np.asarray(self.Eu) <= 0):
            raise LayerstackError("CauchyUrbach.Eu (Urbach energy) must be > 0")

    def __call__(self, wavelength_nm):
        lam2 = (jnp.asarray(wavelength_nm) * 1e-3) ** 2
        n = self.A + self.B / lam2 + self.C / lam2**2
        k = self.k0 * jnp.exp((photon_energy(wavelength_nm) - self.Eb) / self.Eu)
        return complex_from(n, k)
