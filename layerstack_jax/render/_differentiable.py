r"""Derivatives of a rendered image with respect to the parameters of a coating.

A picture of a coated object depends on the coating only through its tables (Hirayama §5):
:math:`I = R(k_r, k_d)`, :math:`(k_r, k_d) = T(\theta)` with :math:`\theta` a film thickness,
an index, the roughness σ0, … The gradient of a scalar function of the image is the chain

.. math:: \frac{\partial \ell}{\partial \theta}
   = \Big(\frac{\partial (k_r, k_d)}{\partial \theta}\Big)^{\!\top}
     \Big(\frac{\partial I}{\partial (k_r, k_d)}\Big)^{\!\top} \frac{\partial \ell}{\partial I},

whose right factor is Mitsuba's reverse-mode derivative of the rendered image with respect to
the table values (Dr.Jit's automatic differentiation through the plugin's gathers,
:mod:`layerstack_jax.render._wavefront`) and whose left factor is JAX's vector–Jacobian product
of the tables with respect to the coating (:func:`coating_table_values`, the physics of
:func:`layerstack_jax.coating_tables` as a JAX function). :func:`render_vjp` composes the two.

How the image is differentiated: the scene's own integrator (e.g. Mitsuba's ``path``) runs with
Dr.Jit's loops and calls evaluated rather than recorded symbolically, so that the whole
computation is on Dr.Jit's AD graph (memory grows with the image, the samples and the depth:
meant for small pictures). The derivative is that of the Monte-Carlo estimate for the given
seed: the sampling densities of the coated BSDF stay those of the tables it was made with, so
the paths do not move when the tables change, and central differences of two renders with the
same seed converge to it. Mitsuba's path-replay integrators (``prb``) are not used: they
re-evaluate ``bsdf.eval``, which is zero for the delta (mirror) lobe, and would drop the
derivative of :math:`k_r` along mirror paths.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .._appearance.render_tables import _diffuse_block, _specular_tables
from .._base.validate import LayerstackError
from ._mitsuba import import_mitsuba

__all__ = ["coating_table_values", "render_vjp"]


def coating_table_values(stack, wavelength_nm, cos_theta, cos_theta_out=None, phi_out=None, *, sigma_nm=0.0,
                         tau_nm=300.0, form: str = "radiometric", shadowing_form: str = "corrected", uniform_albedo=0.0,
                         n_terms: int = 40) -> dict:
    """The tables of :func:`layerstack_jax.coating_tables` on given grids, as JAX arrays
    differentiable with respect to every parameter of ``stack`` and to ``sigma_nm``, ``tau_nm``.

    Args:
        stack: ambient · coherent films · :class:`~layerstack_jax.Substrate` (a JAX pytree: its
            thicknesses and indices may be traced).
        wavelength_nm: ``(L,)``; cos_theta: ``(A,)`` incidence cosines (the light).
        cos_theta_out, phi_out: ``(B,)``, ``(P,)`` outgoing grids of ``k_d``; None for
            specular tables only.
        sigma_nm, tau_nm, form, shadowing_form, uniform_albedo: as in ``coating_tables``.
        n_terms: terms of He's series for ``k_d`` (static; a traced σ0 cannot choose it).

    Returns:
        ``{"k_r": (A, L)}`` and, with outgoing grids, ``"k_d": (A, B, P, L)`` (1/sr).
    """
    wl = jnp.asarray(wavelength_nm)
    cos = jnp.asarray(cos_theta)
    sigma0, tau = jnp.asarray(sigma_nm, dtype=wl.dtype), jnp.asarray(tau_nm, dtype=wl.dtype)
    k_r, _ = _specular_tables(stack, wl, cos, sigma0, tau, shadowing_form)
    out = {"k_r": k_r}
    if cos_theta_out is not None:
        out["k_d"] = _diffuse_block(stack, wl, cos, jnp.asarray(cos_theta_out), jnp.asarray(phi_out), sigma0, tau,
                                    jnp.asarray(uniform_albedo, dtype=wl.dtype), int(n_terms), form, shadowing_form)
    return out


def _table_keys(params, bsdf):
    """The scene-parameter keys of ``bsdf``'s ``k_r`` and ``k_d``."""
    keys = {}
    for key in params.keys():
        node = params.properties[key][2]
        if getattr(node, "surface_id", None) == getattr(bsdf, "surface_id", object()):
            keys[key.rsplit(".", 1)[-1]] = key
    if set(keys) != {"k_r", "k_d"}:
        raise LayerstackError("bsdf is not a coated BSDF of this scene (make it with coated_bsdf(tables) in a vectorized "
                              "variant and put it in the scene)")
    return keys


def render_vjp(scene, bsdf, tables_fn, theta, *, seed: int = 0, spp: int | None = None, sensor: int = 0):
    """Render ``scene`` with the coated BSDF ``bsdf``'s tables set to ``tables_fn(theta)``, and
    the pullback of the image to ``theta``.

    Args:
        scene: a loaded Mitsuba scene (an ``*_ad_*`` vectorized variant, e.g. ``llvm_ad_spectral``)
            that contains ``bsdf``.
        bsdf: the object returned by :func:`~layerstack_jax.render.coated_bsdf`.
        tables_fn: ``theta -> {"k_r": (A, L), "k_d": (A, B, P, L)}`` (``"k_d"`` optional: it then
            keeps the BSDF's values), a JAX function (e.g. built on :func:`coating_table_values`)
            whose tables have the shapes of those the BSDF was made with.
        theta: any JAX pytree of parameters.
        seed, spp: the render's seed and samples per pixel (default: the sensor's sampler).
        sensor: index of the sensor.

    Returns:
        ``(image, vjp)``: the image ``(H, W, C)`` as numpy float32, and ``vjp(cotangent)``, which
        takes ``∂ℓ/∂I`` ``(H, W, C)`` and returns ``∂ℓ/∂θ`` (the pytree of ``theta``); it may be
        called once.
    """
    mi, dr = import_mitsuba()
    if "_ad_" not in (mi.variant() or ""):
        raise LayerstackError(f"render_vjp needs a differentiable vectorized Mitsuba variant (e.g. 'llvm_ad_spectral'), "
                              f"got {mi.variant()!r}")
    params = mi.traverse(scene)
    keys = _table_keys(params, bsdf)
    tables, pullback = jax.vjp(tables_fn, theta)
    if not isinstance(tables, dict) or "k_r" not in tables:
        raise LayerstackError("tables_fn must return a dict with 'k_r' (and optionally 'k_d')")
    names = [n for n in ("k_r", "k_d") if n in tables]
    for n in names:
        size = dr.width(params[keys[n]])
        if np.size(tables[n]) != size:
            raise LayerstackError(f"tables_fn's {n} has {np.size(tables[n])} values, the BSDF's {size}: make the BSDF from "
                                  "tables on the same grids (every grid with at least 2 nodes)")
        params[keys[n]] = mi.Float(np.asarray(tables[n], dtype=np.float32).ravel())
        dr.enable_grad(params[keys[n]])
    params.update()
    with dr.scoped_set_flag(dr.JitFlag.SymbolicLoops, False), dr.scoped_set_flag(dr.JitFlag.SymbolicCalls, False):
        image = scene.integrator().render(scene, scene.sensors()[sensor], seed=seed, spp=spp or 0, develop=True,
                                          evaluate=False)
    primal = np.array(dr.detach(image))
    used = [False]

    def vjp(cotangent):
        if used[0]:
            raise LayerstackError("render_vjp's vjp may be called once (render again for another cotangent)")
        used[0] = True
        ct = np.asarray(cotangent, dtype=np.float32)
        if ct.shape != primal.shape:
            raise LayerstackError(f"cotangent must have the image's shape {primal.shape}, got {ct.shape}")
        dr.backward_from(dr.sum(image * mi.TensorXf(ct), axis=None))
        grads = {n: jnp.asarray(np.array(dr.grad(params[keys[n]]), dtype=np.float64).reshape(np.shape(tables[n])),
                                dtype=jnp.asarray(tables[n]).dtype) for n in names}
        for n in names:
            dr.disable_grad(params[keys[n]])
        return pullback({n: grads[n] for n in tables})[0]

    return primal, vjp
