r"""Virtual varnish removal: a fitted painting predicted without its varnish (or under a fresh
one), as spectra and as sRGB colours — the conservator's first question, "what is under it?".

A fit of a varnished paint (a :class:`~layerstack_jax.KubelkaMunk` body or a Lambertian
background under an absorbing varnish) determines the body (concentrations, ρg) and the varnish
(thickness, α) together. Removing the varnish is then a prediction: the same body with the layer
taken out of the stack (its air–binder interface now the top surface), or with another layer in
its place, read by the same instrument. Nothing is re-fitted; the result is as good as the fit
(its standard errors, and the identifiability findings of the fit, say how good).

Works on one fit (``result.x``), a batch (``BatchResult.x``, ``(N, P)``) or a cube's maps
(:func:`cube_parameters` gives ``(y, x, P)``): every parameter vector is evaluated by one
compiled program mapped over the vectors in blocks (bounded memory for any cube).
"""

from __future__ import annotations

from typing import NamedTuple, Optional

import jax
import jax.numpy as jnp
import numpy as np

from layerstack_jax import (
    ColourSpace,
    Geometry,
    Layer,
    LayerstackError,
    Stack,
    reflectance,
)

from ._cube_store import cube_parameters
from ._objective import Objective

__all__ = ["VarnishRemoval", "varnish_removal", "cube_parameters"]

#: Parameter vectors evaluated together in one step of the mapped program.
BLOCK = 256


class VarnishRemoval(NamedTuple):
    """Spectra ``(*batch, wl)`` (dimensionless readings of ``geometry``) of the fitted stacks as
    they are (``varnished``) and without the layer (``removed``); with a colour space, their sRGB
    (gamma-encoded, clipped to [0, 1]) ``(*batch, 3)``, else None."""

    wavelength_nm: np.ndarray
    varnished: np.ndarray
    removed: np.ndarray
    srgb_varnished: Optional[np.ndarray]
    srgb_removed: Optional[np.ndarray]


def _without(stack: Stack, layer: str, replacement: Optional[Layer]) -> Stack:
    names = [lay.name for lay in stack.layers]
    if layer not in names:
        raise LayerstackError(f"varnish_removal: no layer named {layer!r} in the stack (layers: "
                              f"{', '.join(repr(n) for n in names) or 'none'})")
    i = names.index(layer)
    layers = list(stack.layers[:i]) + ([replacement] if replacement is not None else []) + list(stack.layers[i + 1:])
    return Stack(stack.ambient, layers, stack.exit)


def varnish_removal(objective: Objective, x, *, layer: str = "varnish", replacement: Optional[Layer] = None,
                    geometry: Optional[Geometry] = None, colour_space: Optional[ColourSpace] = None,
                    sample: int = 0) -> VarnishRemoval:
    """The fitted stacks of ``objective`` at parameters ``x`` with and without the layer
    ``layer`` (module docstring).

    Args:
        objective: the :class:`~fitting.Objective` that was fitted.
        x: fitted parameters ``(P,)`` or ``(*batch, P)`` (``FitResult.x``, ``BatchResult.x``,
            :func:`cube_parameters` of a cube's maps). NaN rows (fits not made) give NaN.
        layer: name of the layer to take out (the varnish).
        replacement: a :class:`~layerstack_jax.Layer` put in its place (a fresh varnish), or
            None to leave the paint bare.
        geometry: the instrument to read them with (default: the objective's first dataset's).
        colour_space: a :class:`~layerstack_jax.ColourSpace` on the objective's grid for sRGB
            colours (its grid must be the objective's), or None.
        sample: which sample's stack (per-sample parameters), default 0.
    """
    wl = np.asarray(objective.wavelength, float)
    geometry = objective.datasets[0].geometry if geometry is None else geometry
    x = np.asarray(x, float)
    n_free = len(objective.layout.names)
    if x.shape[-1:] != (n_free,):
        raise LayerstackError(f"varnish_removal: x must end in the objective's {n_free} free parameters "
                              f"({', '.join(objective.layout.names)}), got shape {x.shape}")
    if colour_space is not None and not np.array_equal(np.asarray(colour_space.wavelength_nm), wl):
        raise LayerstackError("varnish_removal: colour_space must be built on the objective's wavelength grid")
    _without(objective.stack, layer, replacement)  # the layer exists: say so before any compute
    batch = x.shape[:-1]
    rows = x.reshape(-1, n_free)
    ok = np.all(np.isfinite(rows), axis=-1)
    safe = np.where(ok[:, None], rows, np.asarray(objective.layout.x0, float))

    def both(xi):
        st = objective.stack_for(xi, sample)
        return reflectance(st, wl, geometry), reflectance(_without(st, layer, replacement), wl, geometry)

    with_layer, without_layer = jax.jit(lambda xs: jax.lax.map(both, xs, batch_size=BLOCK))(jnp.asarray(safe))
    def nan(a):  # NaN for the fits not made, whatever axes follow the row (angles, wavelengths, RGB)
        a = np.asarray(a)
        return np.where(ok.reshape((-1,) + (1,) * (a.ndim - 1)), a, np.nan)

    varnished, removed = nan(with_layer), nan(without_layer)
    srgb = [None, None]
    if colour_space is not None:
        srgb = [nan(colour_space.sRGB(np.nan_to_num(s), clip=True)).reshape(batch + (3,)) for s in (varnished, removed)]
    return VarnishRemoval(wl, varnished.reshape(batch + varnished.shape[1:]),
                          removed.reshape(batch + removed.shape[1:]), *srgb)
