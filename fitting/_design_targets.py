r"""Design targets and their merit: what a coating must do (:class:`SpectralTarget`,
:class:`ColourTarget`) and how far a stack is from it (:func:`merit`).

The merit function is a weighted sum over targets of mean squared, tolerance-scaled deviations,

.. math::
    M(\mathbf d) = \sum_k \frac{w_k}{N_k}\sum_{i} \Big(\frac{Q_k(\lambda_i, \theta_i; \mathbf d)
    - Q^\text{target}_{k,i}}{\delta_{k,i}}\Big)^2,

with :math:`Q` a reflectance, transmittance or absorptance of the stack
(:func:`layerstack_jax.specular`, natural or polarized light). ``'below'`` / ``'above'`` targets
penalise only the side that violates the bound (a one-sided tolerance band), as thin-film
design programs do. The
design optimisers (:mod:`fitting._design`, :mod:`fitting._needle`) minimise it.

Units: thicknesses in nm, wavelengths in nm, angles in degrees (these are the edges).
"""

from __future__ import annotations

from typing import Literal, Sequence

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Real

import layerstack_jax as ls
from layerstack_jax import LayerstackError

__all__ = ["SpectralTarget", "ColourTarget", "merit"]


class SpectralTarget(eqx.Module):
    """A spectral design target.

    Attributes:
        wavelength_nm: wavelengths in nm, shape ``(W,)``.
        value: target values (R, T, A are dimensionless fractions), broadcastable to shape
            ``(A, W)`` (A = number of angles).
        tolerance: tolerance (> 0) of each point, broadcastable to ``(A, W)``: deviations are
            measured in units of it.
        quantity: ``'R'`` (reflectance), ``'T'`` (transmittance into the exit medium) or ``'A'``
            (absorptance 1 − R − T), for light from the ambient.
        angle_deg: ``(A,)`` angles of incidence in degrees (default normal incidence).
        polarization: ``'natural'`` (mean of s and p), ``'s'`` or ``'p'``.
        kind: ``'equal'`` (two-sided), ``'below'`` (Q ≤ value) or ``'above'`` (Q ≥ value).
        weight: weight of this target in the merit.
    """

    wavelength_nm: Float[Array, " W"] = eqx.field(converter=jnp.asarray)
    value: Real[Array, "..."] = eqx.field(converter=jnp.asarray)
    tolerance: Real[Array, "..."] = eqx.field(converter=jnp.asarray, default=0.01)
    quantity: Literal["R", "T", "A"] = eqx.field(static=True, default="R")
    angle_deg: Float[Array, " A"] = eqx.field(converter=lambda a: jnp.atleast_1d(jnp.asarray(a, float)), default=0.0)
    polarization: Literal["natural", "s", "p"] = eqx.field(static=True, default="natural")
    kind: Literal["equal", "below", "above"] = eqx.field(static=True, default="equal")
    weight: float = 1.0

    def __check_init__(self):
        if self.quantity not in ("R", "T", "A"):
            raise LayerstackError(f"SpectralTarget.quantity must be 'R', 'T' or 'A', got {self.quantity!r}")
        if self.polarization not in ("natural", "s", "p"):
            raise LayerstackError(
                f"SpectralTarget.polarization must be 'natural', 's' or 'p', got {self.polarization!r}"
            )
        if self.kind not in ("equal", "below", "above"):
            raise LayerstackError(f"SpectralTarget.kind must be 'equal', 'below' or 'above', got {self.kind!r}")
        if self.wavelength_nm.ndim != 1:
            raise LayerstackError(f"SpectralTarget.wavelength_nm must be 1-D, got shape {self.wavelength_nm.shape}")
        tol = np.asarray(self.tolerance)
        if np.any(~np.isfinite(tol)) or np.any(tol <= 0):
            raise LayerstackError("SpectralTarget.tolerance must be finite and > 0")
        if np.any(~np.isfinite(np.asarray(self.value))):
            raise LayerstackError("SpectralTarget.value contains NaN or infinite values")
        angles = np.asarray(self.angle_deg)
        if np.any(angles < 0) or np.any(angles >= 90):
            raise LayerstackError("SpectralTarget.angle_deg must lie in [0, 90) degrees")
        try:
            np.broadcast_shapes(np.shape(self.value), (angles.size, self.wavelength_nm.size))
            np.broadcast_shapes(np.shape(tol), (angles.size, self.wavelength_nm.size))
        except ValueError:
            raise LayerstackError(
                f"SpectralTarget.value {np.shape(self.value)} / tolerance {np.shape(tol)} do not broadcast to "
                f"(angles, wavelengths) = ({angles.size}, {self.wavelength_nm.size})"
            ) from None

    def evaluate(self, stack: ls.Stack) -> Float[Array, "A W"]:
        """The targeted quantity of ``stack``, shaped ``(A, W)``."""
        out = ls.specular(stack, self.wavelength_nm, self.angle_deg, both_sides=False)  # degrees
        R, T = out.R_front, out.T_front  # (A, 2, W)
        if self.polarization == "natural":
            R, T = 0.5 * (R[:, 0] + R[:, 1]), 0.5 * (T[:, 0] + T[:, 1])
        else:
            i = 0 if self.polarization == "s" else 1
            R, T = R[:, i], T[:, i]
        return {"R": R, "T": T, "A": 1.0 - R - T}[self.quantity]

    def deviation(self, stack: ls.Stack) -> Float[Array, "A W"]:
        """Signed violation in units of the tolerance (0 inside a one-sided band)."""
        x = (self.evaluate(stack) - self.value) / self.tolerance
        if self.kind == "below":
            return jnp.maximum(x, 0.0)
        if self.kind == "above":
            return jnp.minimum(x, 0.0)
        return x

    def merit(self, stack: ls.Stack):
        """``weight · mean(deviation²)``."""
        return self.weight * jnp.mean(self.deviation(stack) ** 2)

    def within_spec(self, stack: ls.Stack):
        """True where every point lies within its tolerance (|deviation| ≤ 1)."""
        return jnp.all(jnp.abs(self.deviation(stack)) <= 1.0)


class ColourTarget(eqx.Module):
    """A colour design target: the CIELAB colour of the stack's specular reflectance (natural
    light) under the illuminant and observer of ``colour_space``, at one or more angles.

    Attributes:
        colour_space: a :class:`layerstack_jax.ColourSpace` (its grid is the evaluation grid).
        lab: target L*, a*, b* (CIELAB, dimensionless), shape ``(3,)`` or ``(A, 3)``.
        angle_deg: ``(A,)`` angles of incidence, degrees.
        tolerance: ΔE2000 counted as one unit of deviation (within spec: ΔE2000 ≤ tolerance).
        weight: weight in the merit.
    """

    colour_space: ls.ColourSpace
    lab: Real[Array, "*A 3"] = eqx.field(converter=jnp.asarray)
    angle_deg: Float[Array, " A"] = eqx.field(converter=lambda a: jnp.atleast_1d(jnp.asarray(a, float)), default=0.0)
    tolerance: float = 1.0
    weight: float = 1.0

    def __check_init__(self):
        if np.shape(self.lab)[-1:] != (3,) or np.any(~np.isfinite(np.asarray(self.lab))):
            raise LayerstackError(f"ColourTarget.lab must be finite L*, a*, b* values (..., 3), got {np.shape(self.lab)}")
        if not float(self.tolerance) > 0:
            raise LayerstackError("ColourTarget.tolerance (ΔE2000) must be > 0")
        angles = np.asarray(self.angle_deg)
        if np.any(angles < 0) or np.any(angles >= 90):
            raise LayerstackError("ColourTarget.angle_deg must lie in [0, 90) degrees")

    def evaluate(self, stack: ls.Stack) -> Float[Array, "A 3"]:
        """CIELAB of the natural-light specular reflectance at each angle, ``(A, 3)``."""
        wl = jnp.asarray(self.colour_space.wavelength_nm)
        R = ls.specular(stack, wl, self.angle_deg, both_sides=False).R_front  # degrees
        return self.colour_space.Lab(0.5 * (R[:, 0] + R[:, 1]))

    def deviation(self, stack: ls.Stack) -> Float[Array, " A"]:
        """ΔE2000 to the target in units of the tolerance."""
        return ls.delta_e_2000(self.evaluate(stack), self.lab) / self.tolerance

    def merit(self, stack: ls.Stack):
        return self.weight * jnp.mean(self.deviation(stack) ** 2)

    def within_spec(self, stack: ls.Stack):
        return jnp.all(self.deviation(stack) <= 1.0)


def merit(stack: ls.Stack, targets: Sequence):
    """Total merit of ``stack`` against ``targets`` (:class:`SpectralTarget`,
    :class:`ColourTarget`): the sum of their ``merit`` — each a weighted mean of squared
    deviations in units of the target's tolerance, so a dimensionless scalar."""
    if not targets:
        raise LayerstackError("design needs at least one target")
    return sum(t.merit(stack) for t in targets)
