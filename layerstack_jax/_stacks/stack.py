r"""Stack description as pytrees: layers, the exit medium, and the stack.

A stack is ambient · layers 1..K · exit medium, ordered from the side the light comes from.
The exit is any :class:`ExitMedium`: a specular :class:`Substrate` (semi-infinite medium), a
:class:`LambertianBackground` (a diffusing medium of index :math:`n_g` and intrinsic reflectance
:math:`\rho_g`, Simonot et al. §4), or a scattering body that lowers itself to such a ρg (a
Kubelka–Munk body, :mod:`layerstack_jax._stacks.kubelka_munk`). Code outside an exit's own module never
asks which class an exit is: it asks the interface (``diffuse``, ``lower``) or the resolved
stack (``rho_g is None``). Structure (number of layers, which are coherent) is static; every
number (indices, thicknesses, α, ρg) is a pytree leaf that can be traced, vmapped and
differentiated; each field declares its role (batch axes, fixed optics, file key) where it is
defined (:mod:`layerstack_jax._base.leaves`).
"""

from __future__ import annotations

import abc
import functools
from typing import ClassVar, NamedTuple, Optional

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._base.custom_types import IndexSpectrum, RealLike, RealSpectrumLike, TableColumn, Wavelengths
from .._base.leaves import leaf
from .._base.validate import (
    LayerstackError,
    PendingChecks,
    check,
    check_nonnegative,
    check_positive,
    check_unit_interval,
    is_concrete,
    value_text,
    warn_if,
    warn_if_implausible,
)
from .._media.materials import Index, Material, Tabulated, as_material

__all__ = [
    "Layer",
    "ExitMedium",
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
        index: material or number (n, or complex n + ik) — see :mod:`layerstack_jax._media.materials`.
        thickness: nm (>= 0); scalar or array broadcastable to ``(*batch, wl)``.
        coherent: True for a thin film (amplitudes add with phase), False for a thick layer
            (intensities add, Beer attenuation). Static.
        alpha: optional absorption coefficient in 1/nm of an incoherent layer (Simonot eq. 20);
            scalar, or array on the model wavelength grid. For a coherent layer give k instead
            (α = 4πk/λ).
        name: label used in messages and files.
    """

    index: Material = leaf(converter=as_material)
    thickness: RealLike = leaf(spectral=True, fixed_optics=lambda layer: not layer.coherent, file_key="thickness_nm")
    coherent: bool = eqx.field(static=True, default=True)
    alpha: Optional[RealSpectrumLike] = leaf(spectral=True, fixed_optics=True, per_wavelength=True,
                                             file_key="alpha_per_nm", default=None)
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


class ExitMedium(eqx.Module):
    r"""What lies under the last layer — the interface every exit medium implements.

    Narrow on purpose (like optimistix's ``AbstractSearch``): the recursion needs of an exit only
    its index and, for a body that sends light back diffusely, its internal diffuse reflectance
    :math:`\rho_g(\lambda)` (Simonot et al. §4: the probability that light which crossed the
    binder interface into the body comes back, Lambertian). An exit *lowers itself* to these on a
    wavelength grid (:meth:`lower`); how it computes ρg (a given spectrum, Kubelka's solution for
    a scattering layer over a ground …) is its own business.

    Attributes:
        index: the index of the medium the light enters from the last layer (a diffusing body's
            binder; real for a diffusing body: light is integrated over angles in it).
        diffuse: class constant — True if the body returns light diffusely (it lowers to a ρg),
            False for a specular exit (it lowers to None).
        table: class constant — the stack-file table that declares this exit (``substrate``,
            ``background`` …).
        label: class constant — how messages and plot titles name it.
    """

    index: eqx.AbstractVar[Material]
    diffuse: eqx.AbstractClassVar[bool]
    table: eqx.AbstractClassVar[str]
    label: eqx.AbstractClassVar[str]

    @abc.abstractmethod
    def lower(self, wavelength_nm) -> Optional[RealLike]:
        r"""The internal diffuse reflectance :math:`\rho_g` on ``wavelength_nm`` (nm, ``(wl,)``),
        dimensionless in [0, 1], broadcastable to ``(*batch, wl)``; None for a specular exit.
        Traced inputs are checked here (``equinox.error_if``); concrete ones at construction."""


class Substrate(ExitMedium):
    """Specular semi-infinite exit medium (glass, silicon, a bulk metal …).

    Attributes:
        index: material or number (n, or complex n + ik, dimensionless); a scalar or an array
            broadcastable to ``(*batch, wl)``. Absorbing (k > 0) is allowed here.
    """

    index: Material = leaf(converter=as_material)
    diffuse: ClassVar[bool] = False
    table: ClassVar[str] = "substrate"
    label: ClassVar[str] = "substrate"

    def lower(self, wavelength_nm) -> None:
        return None


class LambertianBackground(ExitMedium):
    r"""Lambertian diffusing background under the stack (Simonot et al. §4).

    Attributes:
        index: index :math:`n_g` of the background's binder (real).
        reflectance: intrinsic reflectance :math:`\rho_g` in [0, 1]; scalar, array on the model
            wavelength grid, or a :class:`~layerstack_jax.Tabulated`-like spectrum (callable).
    """

    index: Material = leaf(converter=as_material)
    reflectance: RealSpectrumLike = leaf(spectral=True, fixed_optics=True, per_wavelength=True, file_key="rho_g")
    diffuse: ClassVar[bool] = True
    table: ClassVar[str] = "background"
    label: ClassVar[str] = "Lambertian background"

    def __check_init__(self):
        if not callable(self.reflectance):
            check_unit_interval("background reflectance rho_g", self.reflectance)

    def lower(self, wavelength_nm):
        return as_spectrum(self.reflectance, wavelength_nm)


class Stack(eqx.Module):
    """Ambient · layers · exit. Build with numbers or materials:

    >>> Stack(ambient=1.0, layers=[Layer(1.5, 20_000.0, coherent=False, alpha=1e-5)],
    ...       exit=LambertianBackground(1.5, 0.8))  # doctest: +SKIP
    """

    ambient: Material = leaf(converter=as_material)
    layers: tuple = eqx.field(converter=tuple)
    exit: ExitMedium

    def __check_init__(self):
        for i, layer in enumerate(self.layers):
            if not isinstance(layer, Layer):
                raise LayerstackError(f"layers[{i}] is not a Layer: {layer!r}")
        if not isinstance(self.exit, ExitMedium):
            raise LayerstackError("exit must be an exit medium (a Substrate, a LambertianBackground, a KubelkaMunk "
                                  f"body …), got {self.exit!r}")
        for name, mat in (("ambient", self.ambient), ("exit", self.exit.index)):
            if isinstance(mat, Index) and is_concrete(mat.k) and np.any(np.asarray(mat.k) != 0):
                if name == "ambient" or self.exit.diffuse:
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
    values: TableColumn
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

    n: tuple[IndexSpectrum, ...]
    d: tuple[RealLike, ...]
    alpha: tuple[Optional[RealLike], ...]
    coherent: tuple[bool, ...]
    rho_g: Optional[RealLike]
    wavelength: Wavelengths


def _check_index(name: str, n, **pending):
    """A medium's complex index n + ik, checked: finite, n > 0, k ≥ 0 (convention n + ik)."""
    return check(name, n, lambda a, xp: ~xp.isfinite(a) | (xp.real(a) <= 0) | (xp.imag(a) < 0),
                 "must have n > 0 and k >= 0 (convention n + ik)", **pending)


def _warn_implausible(stack: Stack, wl, n: tuple) -> None:
    """Plausibility warnings on the indices and the grid (:func:`~layerstack_jax._base.validate.warn_if`:
    at once on concrete inputs, as outputs of a public program on traced ones)."""
    warn_if_implausible("wavelength_nm", wl, lambda a, xp: (a < 100) | (a > 50_000),
                        "outside 100 nm - 50 µm: wavelengths are in nm (µm given?)")
    for i, (layer, ni) in enumerate(zip(stack.layers, n[1:-1])):
        label = _layer_label(i, layer)
        if layer.coherent and np.shape(wl)[-1] >= 5:  # a few points are not a spectrum that aliases
            warn_if((layer.thickness, ni, wl), _fringes_alias, functools.partial(_aliasing_message, label))
        if layer.alpha is not None:
            warn_if(ni, lambda a, xp: xp.imag(a) > 0,
                    lambda a: f"{label}: both k (in the index) and alpha are given; their absorptions add "
                              "(alpha_total = alpha + 4 pi k / lambda): give one of them")


def _layer_label(i: int, layer: Layer) -> str:
    return f"layers[{i}] ({layer.name or 'unnamed'})"


def _fringes_alias(values, xp):
    """Interference fringes of a coherent film, period λ²/(2 n d) in wavelength, with fewer than 2
    grid points per fringe: the computed spectrum aliases (float32 and float64 then disagree)."""
    d, ni, w = values
    return _fringe_period(d, ni, w, xp) < 2.0 * xp.max(xp.diff(w))


def _fringe_period(d, ni, w, xp):
    optical = 2.0 * xp.max(xp.real(ni)) * xp.max(d)
    return xp.min(w) ** 2 / xp.maximum(optical, 1e-300)


def _aliasing_message(label: str, values) -> str:
    d, ni, w = values
    return (f"{label}: coherent film of {np.max(d):g} nm has fringes every {_fringe_period(d, ni, w, np):.3g} nm, "
            f"finer than twice the grid step ({np.max(np.diff(w)):g} nm): the spectrum aliases; "
            "should it be coherent = false (a thick layer)?")


def _warn_units(stack: Stack, wl, d: list, alpha: list) -> None:
    """Unit slips that would otherwise end in a plausible-looking wrong spectrum: a thick layer's
    thickness given in µm (30 for 30 µm: a 30 nm "thick" layer, i.e. no layer), α in 1/cm or 1/µm
    (20/cm read as 20/nm: an opaque layer, a spectrum of the front reflection only)."""
    for i, (layer, h, a) in enumerate(zip(stack.layers, d, alpha)):
        label = _layer_label(i, layer)
        if not layer.coherent:
            warn_if((h, wl), lambda v, xp: (v[0] > 0) & (v[0] < xp.max(v[1])),
                    lambda v, label=label: f"{label}: thickness (nm) {value_text(v[0])}: an incoherent (thick) layer "
                    f"thinner than the longest wavelength ({np.max(v[1]):g} nm): thicknesses are in nm (µm given? "
                    "30 µm = 30000 nm); a film this thin is coherent (coherent = true)")
        if a is not None:
            warn_if(a, lambda v, xp: v > 1.0,
                    lambda v, label=label: f"{label}: alpha (1/nm) {value_text(v)}: an absorption length below 1 nm "
                    "(no material absorbs that strongly): alpha is in 1/nm (1/cm given? 1/cm = 1e-7/nm; "
                    "1/µm = 1e-3/nm)")


def resolve(stack: Stack, wavelength_nm) -> ResolvedStack:
    """Sample every material and spectrum of ``stack`` on ``wavelength_nm`` (nm), checking every
    physical constraint on the way — eagerly on concrete values, with ``equinox.error_if`` on
    traced ones (:mod:`layerstack_jax._base.validate`): λ > 0, n > 0, k ≥ 0, thickness ≥ 0, α ≥ 0,
    0 ≤ ρg ≤ 1, each message naming the field."""
    wl = jnp.asarray(wavelength_nm) if not is_concrete(wavelength_nm) else np.asarray(wavelength_nm)
    if wl.ndim != 1:
        raise LayerstackError(f"wavelength_nm must be 1-D, got shape {wl.shape}")
    checks = PendingChecks()  # traced checks: one runtime branch for the whole stack
    wl = check_positive("wavelength_nm (nm)", wl, pending=checks, key=("wl",))
    names = ("ambient index", *(f"layers[{i}] ({layer.name or 'unnamed'}): index" for i, layer in enumerate(stack.layers)),
             "exit index")
    n = [
        _check_index(name, m(wl), pending=checks, key=("n", i))  # numpy when concrete: static work at trace time
        for i, (name, m) in enumerate(zip(names, (stack.ambient, *(layer.index for layer in stack.layers),
                                                   stack.exit.index)))
    ]
    _warn_implausible(stack, wl, n)
    rho_g = stack.exit.lower(wl)
    if rho_g is not None:
        rho_g = _on_grid("background reflectance rho_g", rho_g, wl)
        rho_g = check_unit_interval("background reflectance rho_g", rho_g, pending=checks, key=("rho_g",))
    d, alpha = [], []
    for i, layer in enumerate(stack.layers):
        label = f"layers[{i}] ({layer.name or 'unnamed'})"
        h = _on_grid(f"{label}: thickness (nm)", layer.thickness, wl)
        d.append(jnp.asarray(check_nonnegative(f"{label}: thickness (nm)", h, pending=checks, key=("d", i))))
        a = None if layer.alpha is None else _on_grid(f"{label}: alpha (1/nm)", as_spectrum(layer.alpha, wl), wl)
        alpha.append(None if a is None else check_nonnegative(f"{label}: alpha (1/nm)", a, pending=checks, key=("alpha", i)))
    _warn_units(stack, wl, d, alpha)
    attached = checks.attach()
    if attached is not None:  # the first traced value carries every traced check
        key, value = attached
        if key[0] == "wl":
            wl = value
        elif key[0] == "n":
            n[key[1]] = value
        elif key[0] == "rho_g":
            rho_g = value
        elif key[0] == "d":
            d[key[1]] = value
        else:
            alpha[key[1]] = value
    wl = jnp.asarray(wl)
    return ResolvedStack(
        n=tuple(n),
        d=tuple(d),
        alpha=tuple(alpha),
        coherent=stack.coherent,
        rho_g=rho_g,
        wavelength=wl,
    )


def _on_grid(name: str, x, wl):
    """A per-wavelength leaf ends on the wavelength axis: ``(..., 1)`` or ``(..., wl)``."""
    shape = jnp.shape(x)
    if shape and shape[-1] not in (1, wl.shape[-1]):
        raise LayerstackError(f"{name}: an array must have {wl.shape[-1]} values (one per wavelength) on its last "
                              f"axis, got shape {shape}; for a batch of samples use layerstack_jax.predict")
    return x


def check_stack(stack: Stack, wavelength_nm) -> None:
    """Raise :class:`LayerstackError` (naming the field) if ``stack`` cannot be evaluated on
    ``wavelength_nm`` (nm): a wavelength outside a material table's range, k < 0, ρg outside
    [0, 1], a negative thickness or α … — the checks every public function makes, run once up
    front (e.g. before a long batch or a fit)."""
    resolve(stack, wavelength_nm)
