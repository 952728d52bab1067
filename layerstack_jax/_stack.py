r"""Stack description as pytrees: layers, substrate or Lambertian background, and the stack.

A stack is ambient · layers 1..K · exit medium, ordered from the side the light comes from.
The exit is either a specular :class:`Substrate` (semi-infinite medium) or a
:class:`LambertianBackground` (a diffusing medium of index :math:`n_g` and intrinsic reflectance
:math:`\rho_g`, Simonot et al. §4). Structure (number of layers, which are coherent) is static;
every number (indices, thicknesses, α, ρg) is a pytree leaf that can be traced, vmapped and
differentiated.
"""

from __future__ import annotations

from typing import NamedTuple, Optional, Union

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._materials import Index, Material, Tabulated, as_material
from ._validate import LayerstackError, check_nonnegative, check_unit_interval, is_concrete

__all__ = [
    "Layer",
    "Substrate",
    "LambertianBackground",
    "Stack",
    "ResolvedStack",
    "resolve",
    "as_spectrum",
    "TabulatedSpectrum",
]


class Layer(eqx.Module):
    """One layer.

    Attributes:
        index: material or number (n, or complex n + ik) — see :mod:`layerstack_jax._materials`.
        thickness: nm (>= 0); scalar or array broadcastable to ``(*batch, wl)``.
        coherent: True for a thin film (amplitudes add with phase), False for a thick layer
            (intensities add, Beer attenuation). Static.
        alpha: optional absorption coefficient in 1/nm of an incoherent layer (Simonot eq. 20);
            scalar, or array on the model wavelength grid. For a coherent layer give k instead
            (α = 4πk/λ).
        name: label used in messages and files.
    """

    index: Material = eqx.field(converter=as_material)
    thickness: object
    coherent: bool = eqx.field(static=True, default=True)
    alpha: object = None
    name: str = eqx.field(static=True, default="")

    def __check_init__(self):
        label = f"layer {self.name!r}" if self.name else "layer"
        check_nonnegative(f"{label}: thickness (nm)", self.thickness)
        if self.alpha is not None:
            if self.coherent:
                raise LayerstackError(
                    f"{label}: alpha is for incoherent layers; give a coherent film an extinction coefficient k"
                )
            if not callable(self.alpha):
                check_nonnegative(f"{label}: alpha (1/nm)", self.alpha)


class Substrate(eqx.Module):
    """Specular semi-infinite exit medium (glass, silicon, a bulk metal …).

    Attributes:
        index: material or number (n, or complex n + ik, dimensionless); a scalar or an array
            broadcastable to ``(*batch, wl)``. Absorbing (k > 0) is allowed here.
    """

    index: Material = eqx.field(converter=as_material)


class LambertianBackground(eqx.Module):
    r"""Lambertian diffusing background under the stack (Simonot et al. §4).

    Attributes:
        index: index :math:`n_g` of the background's binder (real).
        reflectance: intrinsic reflectance :math:`\rho_g` in [0, 1]; scalar, array on the model
            wavelength grid, or a :class:`~layerstack_jax.Tabulated`-like spectrum (callable).
    """

    index: Material = eqx.field(converter=as_material)
    reflectance: object

    def __check_init__(self):
        if not callable(self.reflectance):
            check_unit_interval("background reflectance rho_g", self.reflectance)


Exit = Union[Substrate, LambertianBackground]


class Stack(eqx.Module):
    """Ambient · layers · exit. Build with numbers or materials:

    >>> Stack(ambient=1.0, layers=[Layer(1.5, 20_000.0, coherent=False, alpha=1e-5)],
    ...       exit=LambertianBackground(1.5, 0.8))  # doctest: +SKIP
    """

    ambient: Material = eqx.field(converter=as_material)
    layers: tuple = eqx.field(converter=tuple)
    exit: Exit

    def __check_init__(self):
        for i, layer in enumerate(self.layers):
            if not isinstance(layer, Layer):
                raise LayerstackError(f"layers[{i}] is not a Layer: {layer!r}")
        if not isinstance(self.exit, (Substrate, LambertianBackground)):
            raise LayerstackError("exit must be a Substrate or a LambertianBackground")
        for name, mat in (("ambient", self.ambient), ("exit", self.exit.index)):
            if isinstance(mat, Index) and is_concrete(mat.k) and np.any(np.asarray(mat.k) != 0):
                if name == "ambient" or isinstance(self.exit, LambertianBackground):
                    raise LayerstackError(f"{name} index must be real (k = 0): light is incident from / integrated in it")

    @property
    def coherent(self) -> tuple:
        """Static coherence pattern of the layers."""
        return tuple(layer.coherent for layer in self.layers)


class TabulatedSpectrum(eqx.Module):
    """A real spectrum (e.g. ρg) tabulated on its own wavelengths, linearly interpolated.

    Never extrapolates: asking outside the table raises :class:`LayerstackError`.

    Attributes:
        wavelength_nm: strictly increasing table wavelengths in nm, shape ``(table,)`` (static).
        values: the spectrum at those wavelengths, shape ``(table,)``, in the spectrum's own
            unit (a dimensionless fraction for ρg).
        name: label used in messages.

    Called with wavelengths in nm of shape ``(wl,)`` it returns a real array ``(wl,)``.
    """

    wavelength_nm: tuple = eqx.field(static=True, converter=lambda x: tuple(np.asarray(x, float).tolist()))
    values: object
    name: str = eqx.field(static=True, default="spectrum")

    def __call__(self, wavelength_nm):
        return jnp.real(Tabulated(self.wavelength_nm, self.values, None, name=self.name)(wavelength_nm))


def as_spectrum(x, wavelength_nm):
    """Evaluate a spectrum given as scalar, array on the grid, or callable on ``wavelength_nm``."""
    return x(wavelength_nm) if callable(x) else jnp.asarray(x)


class ResolvedStack(NamedTuple):
    """A stack sampled on a wavelength grid: what the kernels consume.

    ``n``: complex index of each medium (ambient, layers…, exit), each broadcastable to
    ``(*batch, wl)``; ``d``, ``alpha``: per layer (alpha may be None); ``coherent``: static flags;
    ``rho_g``: background reflectance or None for a substrate; ``wavelength``: nm, ``(wl,)``.
    """

    n: tuple
    d: tuple
    alpha: tuple
    coherent: tuple
    rho_g: Optional[object]
    wavelength: object


def resolve(stack: Stack, wavelength_nm) -> ResolvedStack:
    """Sample every material and spectrum of ``stack`` on ``wavelength_nm`` (nm)."""
    wl = jnp.asarray(wavelength_nm)
    if wl.ndim != 1:
        raise LayerstackError(f"wavelength_nm must be 1-D, got shape {wl.shape}")
    if is_concrete(wl):
        w = np.asarray(wl)
        if np.any(~np.isfinite(w)) or np.any(w <= 0):
            raise LayerstackError("wavelength_nm must be finite and > 0")
    n = tuple(
        m(wl)  # numpy when concrete: lets static work (critical angles) happen at trace time
        for m in (stack.ambient, *(layer.index for layer in stack.layers), stack.exit.index)
    )
    for i, (ni, layer) in enumerate(zip(n[1:-1], stack.layers)):
        if is_concrete(ni):
            k = np.imag(np.asarray(ni))
            if np.any(k < 0):
                raise LayerstackError(f"layers[{i}] ({layer.name or 'unnamed'}): k must be >= 0 (convention n + ik)")
    rho_g = None
    if isinstance(stack.exit, LambertianBackground):
        rho_g = as_spectrum(stack.exit.reflectance, wl)
        check_unit_interval("background reflectance rho_g", rho_g)
    return ResolvedStack(
        n=n,
        d=tuple(jnp.asarray(layer.thickness) for layer in stack.layers),
        alpha=tuple(None if layer.alpha is None else as_spectrum(layer.alpha, wl) for layer in stack.layers),
        coherent=stack.coherent,
        rho_g=rho_g,
        wavelength=wl,
    )


def check_stack(stack: Stack, wavelength_nm) -> None:
    """Raise :class:`LayerstackError` (naming the field) if ``stack`` cannot be evaluated on
    ``wavelength_nm`` (nm): a wavelength outside a material table's range, k < 0, ρg outside
    [0, 1], a negative thickness or α … — the checks every public function makes, run once up
    front (e.g. before a long batch or a fit)."""
    resolve(stack, wavelength_nm)
