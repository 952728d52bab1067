"""Fixed optics (``ls.fixed_optics`` / ``reflectance(..., optics=)``) and the dense-Jacobian
wrapper of the least-squares solvers: the reused pieces give the same numbers as recomputing
everything, and misuse is refused."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import fitting
import layerstack_jax as ls
from fitting._fit_functions import dense_jacobian

WL = np.linspace(420.0, 700.0, 15)


def _stack(h_thick=20_000.0, alpha=2e-5, rho=0.6, film=90.0, exit_="background"):
    exit_medium = (ls.LambertianBackground(1.5, rho * (1 + 0.2 * np.sin(WL / 40))) if exit_ == "background"
                   else ls.Substrate(ls.Index(1.7, 0.02)))
    return ls.Stack(1.0, [
        ls.Layer(ls.Cauchy(1.46, 0.004), film, coherent=True, name="film"),
        ls.Layer(1.55, h_thick, coherent=False, alpha=alpha * (1 + np.cos(WL / 50)), name="varnish"),
        ls.Layer(ls.Index(1.8, 0.01), 60.0, coherent=True, name="film2"),
        ls.Layer(1.45, 5_000.0, coherent=False, alpha=1e-6, name="ink"),
    ], exit_medium)


GEOMETRIES = [ls.Sphere(8.0), ls.Sphere(8.0, "included"), ls.Directional(45.0, 0.0), ls.BRDF(30.0, 10.0),
              ls.Specular(20.0, "R"), ls.Specular(20.0, "T"), ls.Specular(20.0, "A")]


@pytest.mark.parametrize("geometry", GEOMETRIES, ids=lambda g: type(g).__name__ + getattr(g, "quantity", getattr(g, "specular", "")))
def test_optics_reused_for_other_thick_thickness_alpha_and_rho_equal_recomputed(geometry):
    optics = ls.fixed_optics(_stack(), WL, geometry)
    other = _stack(h_thick=35_000.0, alpha=5e-5, rho=0.3)
    reused = ls.reflectance(other, WL, geometry, optics=optics)
    fresh = ls.reflectance(other, WL, geometry)
    assert np.max(np.abs(np.asarray(reused) - np.asarray(fresh))) < 1e-14
    # and the reused optics change the answer when they should: a different stack differs
    assert np.max(np.abs(np.asarray(fresh) - np.asarray(ls.reflectance(_stack(), WL, geometry)))) > 1e-4


def test_optics_over_a_substrate_and_under_jit_and_grad():
    g = ls.Sphere(8.0, "included")
    optics = ls.fixed_optics(_stack(exit_="substrate"), WL, g)
    f = jax.jit(lambda h, o: ls.reflectance(_stack(h_thick=h, exit_="substrate"), WL, g, optics=o))
    assert np.allclose(f(30_000.0, optics), ls.reflectance(_stack(h_thick=30_000.0, exit_="substrate"), WL, g),
                       rtol=0, atol=1e-14)
    g2 = ls.Directional(45.0, 0.0)
    o2 = ls.fixed_optics(_stack(), WL, g2)
    loss = lambda h, o: jnp.sum(ls.reflectance(_stack(h_thick=h), WL, g2, optics=o) ** 2)  # noqa: E731
    d_reused = jax.grad(loss)(25_000.0, o2)
    d_fresh = jax.grad(loss)(25_000.0, None)
    assert abs(float(d_reused) - float(d_fresh)) <= 1e-12 * abs(float(d_fresh)) and float(d_fresh) != 0


def test_optics_refused_for_another_index_film_geometry_or_nodes():
    g = ls.Sphere(8.0)
    optics = ls.fixed_optics(_stack(), WL, g)
    other_index = ls.Stack(1.0, [*_stack().layers[:1], ls.Layer(1.60, 20_000.0, coherent=False, alpha=2e-5),
                                 *_stack().layers[2:]], _stack().exit)
    with pytest.raises(ls.LayerstackError, match="another index"):
        ls.reflectance(other_index, WL, g, optics=optics)
    with pytest.raises(ls.LayerstackError, match="another coherent film thickness"):
        ls.reflectance(_stack(film=120.0), WL, g, optics=optics)
    with pytest.raises(ls.LayerstackError, match="made for Sphere"):
        ls.reflectance(_stack(), WL, ls.Directional(45.0, 0.0), optics=optics)
    with pytest.raises(ls.LayerstackError, match=f"made for Sphere with {ls.DEFAULT_NODES} nodes"):
        ls.reflectance(_stack(), WL, g, nodes=32, optics=optics)
    with pytest.raises(ls.LayerstackError, match="fixed_optics"):
        ls.reflectance(_stack(), WL, g, optics="not optics")


def test_objective_uses_fixed_optics_only_when_no_free_parameter_changes_them():
    y = np.asarray(ls.reflectance(_stack(), WL, ls.Sphere(8.0)))
    ds = fitting.Dataset(ls.Sphere(8.0), y)
    thick = fitting.Objective(_stack(), WL, ds, [fitting.thickness("varnish"), fitting.rho_g(basis=3)])
    assert thick.optics is not None and isinstance(thick.optics[0], ls.Optics)
    film = fitting.Objective(_stack(), WL, ds, [fitting.thickness("film")])
    assert film.optics is None
    # both predict the same spectra as the plain forward model
    x = thick.layout.x0 * 1.1
    assert np.allclose(thick.predict(x, thick.optics)[0], thick.predict(x)[0], rtol=0, atol=1e-14)


def test_dense_jacobian_values_jvp_transpose_and_args_tangents():
    def fn(u, args):
        a, b = args
        return jnp.concatenate([jnp.sin(u * a), jnp.exp(u[:2]) * b, u[:1] ** 3])

    g = dense_jacobian(fn)
    u = jnp.array([0.3, -0.7, 1.1])
    args = (jnp.array([1.0, 2.0, 3.0]), jnp.array(0.5))
    assert np.allclose(g(u, args), fn(u, args), rtol=0, atol=0)
    du = jnp.array([0.2, 0.1, -0.4])
    _, t_dense = jax.jvp(lambda v: g(v, args), (u,), (du,))
    _, t_plain = jax.jvp(lambda v: fn(v, args), (u,), (du,))
    assert np.allclose(t_dense, t_plain, rtol=1e-14, atol=1e-15)
    # reverse mode (transpose of the dense product) equals plain reverse mode
    ct = jnp.arange(6.0)
    assert np.allclose(jax.vjp(lambda v: g(v, args), u)[1](ct)[0], jax.vjp(lambda v: fn(v, args), u)[1](ct)[0],
                       rtol=1e-14, atol=1e-15)
    # tangents of the arguments still flow exactly
    da = (jnp.array([0.1, 0.0, -0.2]), jnp.array(1.0))
    _, ta = jax.jvp(lambda a: g(u, a), (args,), (da,))
    _, tp = jax.jvp(lambda a: fn(u, a), (args,), (da,))
    assert np.allclose(ta, tp, rtol=1e-14, atol=1e-15)
