r"""Effective-medium layers: mixtures of materials (surface roughness, porosity, alloys).

An effective medium is a :class:`~layerstack_jax._media.materials.Material` composed of two or more
materials with volume fractions. It is called like any material (wavelengths in nm → complex
index n + ik) and is a pytree: the constituents' coefficients and the fractions are leaves, so
they can be fitted. Permittivities :math:`\varepsilon_i = \tilde n_i^2`, convention
:math:`e^{-i\omega t}`, :math:`\varepsilon = \varepsilon_1 + i\varepsilon_2` with
:math:`\varepsilon_2 \ge 0` for absorbing media.

Fractions: ``fractions`` holds the volume fractions of the first m − 1 materials; the last
material fills the rest (1 − Σ). A single fitted number thus describes a two-phase mixture, and
the fractions always sum to one. Surface roughness is the classic use: a Bruggeman layer of the
substrate and void (``Index(1.0)``) at 50 % (Aspnes, Theeten & Hottier, Phys. Rev. B 20, 3292
(1979)).

* :class:`Bruggeman` — :math:`\sum_i f_i (\varepsilon_i - \varepsilon)/(\varepsilon_i + 2\varepsilon) = 0`
  (spherical inclusions, no host: every phase is treated alike; Bruggeman, Ann. Phys. 416,
  636 (1935)).
* :class:`Looyenga` — :math:`\varepsilon^{1/3} = \sum_i f_i \varepsilon_i^{1/3}` (Looyenga,
  Physica 31, 401 (1965)).

Branch of the Bruggeman root (absorbing media)
----------------------------------------------
For two phases the condition is the quadratic
:math:`2\varepsilon^2 - b\varepsilon - \varepsilon_a\varepsilon_b = 0`,
:math:`b = (3f_a - 1)\varepsilon_a + (3f_b - 1)\varepsilon_b`, with roots
:math:`\varepsilon_\pm = (b \pm \sqrt{b^2 + 8\varepsilon_a\varepsilon_b})/4`. Their product is
:math:`-\varepsilon_a\varepsilon_b/2`: for passive phases (:math:`\operatorname{Im}\varepsilon_{a,b}
\ge 0`) one root is the physical, passive mixture and the other typically lies in the lower
half plane or on the negative real axis (e.g. equal phases: :math:`\varepsilon` and
:math:`-\varepsilon/2`). The root with the larger :math:`\operatorname{Im}\varepsilon` is taken;
when both are real (lossless phases: the roots then have opposite signs) the positive one. It
tends to :math:`\varepsilon_a` as :math:`f_a \to 1` and to :math:`\varepsilon_b` as
:math:`f_a \to 0` (tests). This is the branch of Jansson & Arwin, Opt.
Commun. 106, 133 (1994), and it agrees with pyElli's ``BruggemanEMA`` (Roussel et al. 1993)
on the cases tested. For m > 2 phases the condition is solved by Newton's method started from
the Looyenga value (which lies on the physical branch), a fixed number of steps (jit- and
grad-compatible).
"""

from __future__ import annotations

from typing import Sequence

import jax.numpy as jnp
import numpy as np

from .._base.custom_types import RealLike
from .._base.numerics import as_complex, complex_from
from .._base.validate import LayerstackError, is_concrete
from .materials import Material, as_material

__all__ = ["Bruggeman", "Looyenga", "bruggeman_two_phase", "looyenga"]

#: Newton steps for Bruggeman mixtures of more than two phases.
_NEWTON_STEPS = 30


def _all_fractions(fractions, m):
    """Volume fractions ``(m, *batch)`` from the first m − 1 (the last fills the rest)."""
    f = jnp.atleast_1d(jnp.asarray(fractions, dtype=float))
    return jnp.concatenate([f, (1.0 - jnp.sum(f, axis=0))[None]], axis=0)


def _check_mixture(name, materials, fractions):
    if len(materials) < 2:
        raise LayerstackError(f"{name}.materials: an effective medium needs at least two materials")
    if is_concrete(fractions):
        f = np.atleast_1d(np.asarray(fractions, dtype=float))
        if f.shape[0] != len(materials) - 1:
            raise LayerstackError(
                f"{name}.fractions: give the volume fractions of the first {len(materials) - 1} "
                f"material(s) (the last fills the rest), got {f.shape[0]}"
            )
        if not np.all(np.isfinite(f)) or np.any(f < 0) or np.any(f > 1) or np.any(f.sum(axis=0) > 1 + 1e-12):
            raise LayerstackError(f"{name}.fractions must lie in [0, 1] and sum to at most 1, got {f.tolist()}")


def bruggeman_two_phase(eps_a, eps_b, f_a):
    r"""Two-phase Bruggeman permittivity (module docstring for the root): phase a with volume
    fraction ``f_a``, phase b with 1 − f_a. Complex ε arrays broadcast together; returns ε."""
    f_b = 1.0 - f_a
    b = as_complex(3 * f_a - 1, eps_a) * eps_a + as_complex(3 * f_b - 1, eps_b) * eps_b
    root = jnp.sqrt(b**2 + 8 * eps_a * eps_b)
    plus, minus = (b + root) / 4, (b - root) / 4
    im_p, im_m = jnp.imag(plus), jnp.imag(minus)
    scale = jnp.abs(plus) + jnp.abs(minus)
    tie = jnp.abs(im_p - im_m) <= 1e-12 * scale
    take_plus = jnp.where(tie, jnp.real(plus) >= jnp.real(minus), im_p > im_m)
    return jnp.where(take_plus, plus, minus)


def _cbrt_upper(eps):
    r"""Principal cube root: for Im ε ≥ 0, arg ∈ [0, π/3]."""
    return as_complex(jnp.abs(eps) ** (1 / 3), eps) * jnp.exp(1j * as_complex(jnp.angle(eps), eps) / 3)


def looyenga(eps, f):
    r"""Looyenga mixture :math:`(\sum_i f_i \varepsilon_i^{1/3})^3` of ε ``(m, *B)`` with
    fractions ``(m, *B')`` (summing to one); returns ``(*B)``. For passive phases every cube
    root has argument in [0, π/3], so their positive combination does too, and the cube lies in
    the upper half plane: passive."""
    roots = _cbrt_upper(eps)
    return jnp.sum(as_complex(f, roots) * roots, axis=0) ** 3


def _bruggeman_newton(eps, f):
    """m-phase Bruggeman by Newton's method from the Looyenga value, ε ``(m, *B)``."""
    e = looyenga(eps, f)
    f = as_complex(f, eps)
    for _ in range(_NEWTON_STEPS):
        g = jnp.sum(f * (eps - e) / (eps + 2 * e), axis=0)
        dg = jnp.sum(f * (-3 * eps) / (eps + 2 * e) ** 2, axis=0)
        e = e - g / dg
    return e


class _Mixture(Material):
    materials: tuple
    fractions: RealLike

    def __init__(self, materials: Sequence, fractions):
        self.materials = tuple(as_material(m) for m in materials)
        self.fractions = fractions
        _check_mixture(type(self).__name__, self.materials, fractions)

    def _permittivities(self, wavelength_nm):
        eps = [jnp.asarray(m(wavelength_nm)) ** 2 for m in self.materials]
        shape = jnp.broadcast_shapes(*(e.shape for e in eps))
        eps = jnp.stack([jnp.broadcast_to(e, shape).astype(complex) for e in eps])
        f = _all_fractions(self.fractions, len(self.materials))
        f = jnp.reshape(f, f.shape + (1,) * max(eps.ndim - f.ndim, 0))
        return eps, f

    def __call__(self, wavelength_nm):
        eps = self.permittivity(wavelength_nm)
        # the constituents are passive (k >= 0 is enforced), so is the mixture: an imaginary
        # part below zero can only be round-off (~1e-17 at f = 0 or 1), clipped so that k >= 0
        return jnp.sqrt(complex_from(jnp.real(eps), jnp.maximum(jnp.imag(eps), 0.0)))


class Bruggeman(_Mixture):
    r"""Bruggeman effective medium of two or more materials (module docstring; root choice for
    absorbing media documented there).

    Args / attributes:
        materials: the constituents (materials or numbers), m ≥ 2.
        fractions: volume fractions of the first m − 1 materials, shape ``(m - 1,)`` or a
            scalar for two phases; in [0, 1]; the last material fills the rest. A JAX leaf
            (fittable).

    Example — surface roughness of silicon: ``Bruggeman([si, 1.0], 0.5)``.

    Called with wavelengths in nm ``(wl,)``, returns n + ik ``(wl,)``.
    """

    def permittivity(self, wavelength_nm):
        """Complex effective ε on the grid (nm)."""
        eps, f = self._permittivities(wavelength_nm)
        if eps.shape[0] == 2:
            return bruggeman_two_phase(eps[0], eps[1], f[0])
        return _bruggeman_newton(eps, f)


class Looyenga(_Mixture):
    r"""Looyenga effective medium :math:`\varepsilon^{1/3} = \sum_i f_i\varepsilon_i^{1/3}`
    of two or more materials (attributes as :class:`Bruggeman`).

    Called with wavelengths in nm ``(wl,)``, returns n + ik ``(wl,)``.
    """

    def permittivity(self, wavelength_nm):
        """Complex effective ε on the grid (nm)."""
        eps, f = self._permittivities(wavelength_nm)
        return looyenga(eps, f)
