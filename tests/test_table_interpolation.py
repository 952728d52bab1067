"""Tables on a fixed wavelength grid are data, not code, in a compiled model (issue 15).

A model's wavelength grid is fixed while a fit or a design varies thicknesses and
coefficients. Material tables (``Tabulated``, database pages, a formula page's k table) are
interpolated on it in numpy when the grid is concrete
(:func:`layerstack_jax._media.materials.interpolate_table`): the compiled model holds the sampled
index — no interval search (``jnp.interp``'s while loops) compiled into it or run at every
solver step. Checked here against ``np.interp`` and ``jnp.interp`` (values, and the
gradient with respect to the table values), on exact nodes and both ends, with the grid
concrete and traced, and in the jaxpr of a compiled model.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import layerstack_jax as ls
from layerstack_jax._media.materials import interpolate_table

TABLE_WL = np.array([300.0, 420.0, 500.0, 650.0, 900.0])
TABLE_N = np.array([1.62, 1.58, 1.55, 1.53, 1.51])
TABLE_K = np.array([0.08, 0.03, 0.01, 0.0, 0.0])
#: the ends, every node, and points between
GRID = np.concatenate([TABLE_WL, [301.5, 419.999, 455.0, 777.7, 899.9]])


def test_concrete_grid_interpolates_as_np_interp():
    for values in (TABLE_N, TABLE_K):
        got = interpolate_table(GRID, TABLE_WL, values)
        assert isinstance(got, np.ndarray)
        np.testing.assert_allclose(got, np.interp(GRID, TABLE_WL, values), rtol=1e-15, atol=1e-17)
        np.testing.assert_array_equal(got[: TABLE_WL.size], values)  # exact on the nodes, both ends included


def test_traced_grid_gives_the_same_values():
    concrete = interpolate_table(GRID, TABLE_WL, TABLE_N)
    traced = jax.jit(lambda x: interpolate_table(x, TABLE_WL, TABLE_N))(jnp.asarray(GRID))
    np.testing.assert_allclose(np.asarray(traced), concrete, rtol=1e-15)
    material = ls.Tabulated(TABLE_WL, TABLE_N, TABLE_K, name="ink")
    eager = np.asarray(material(GRID))
    assert isinstance(material(GRID), np.ndarray)
    np.testing.assert_allclose(np.asarray(jax.jit(lambda x: material(x))(jnp.asarray(GRID))), eager, rtol=1e-15)
    np.testing.assert_allclose(eager, np.interp(GRID, TABLE_WL, TABLE_N) + 1j * np.interp(GRID, TABLE_WL, TABLE_K),
                               rtol=1e-15)


def test_gradient_with_respect_to_table_values_equals_jnp_interp():
    weights = np.linspace(0.5, 2.0, GRID.size)

    def ours(values):
        return jnp.sum(weights * interpolate_table(GRID, TABLE_WL, values))

    def reference(values):
        return jnp.sum(weights * jnp.interp(jnp.asarray(GRID), jnp.asarray(TABLE_WL), values))

    g = jax.jit(jax.grad(ours))(jnp.asarray(TABLE_N))
    np.testing.assert_allclose(np.asarray(g), np.asarray(jax.grad(reference)(jnp.asarray(TABLE_N))), rtol=1e-14)
    assert np.all(np.asarray(g) > 0)  # every node is used by some grid point
    material = lambda n: jnp.sum(jnp.real(ls.Tabulated(TABLE_WL, n, name="ink")(GRID)) * weights)  # noqa: E731
    np.testing.assert_allclose(np.asarray(jax.grad(material)(jnp.asarray(TABLE_N))), np.asarray(g), rtol=1e-14)


def _psi(stack_of, wl):
    return lambda d: ls.ellipsometry(stack_of(d), wl, np.asarray([65.0])).psi_deg


@pytest.mark.parametrize("exit_", ["table", "database"])
def test_compiled_model_on_a_fixed_grid_holds_no_table_search(exit_):
    """The jaxpr of ψ(d) on a numpy grid — a film over a tabulated or database (Aspnes Si)
    substrate — holds no interval search and no loop: the tables were sampled at trace time.
    On a traced grid the search is there (``jnp.interp``), and both give the same ψ."""
    wl = np.linspace(420.0, 800.0, 41)
    sub = ls.Tabulated(TABLE_WL, 3.0 + TABLE_N, TABLE_K, name="table") if exit_ == "table" else ls.material("Si", "Aspnes")

    def stack(d):
        return ls.Stack(1.0, [ls.Layer(ls.Cauchy(1.46, 0.004), d)], ls.Substrate(sub))

    fixed = str(jax.make_jaxpr(_psi(stack, wl))(100.0))
    assert "searchsorted" not in fixed and "while" not in fixed
    traced = str(jax.make_jaxpr(lambda w: ls.ellipsometry(stack(100.0), w, np.asarray([65.0])).psi_deg)(jnp.asarray(wl)))
    assert "searchsorted" in traced
    a = np.asarray(jax.jit(_psi(stack, wl))(100.0))
    b = np.asarray(jax.jit(lambda w: ls.ellipsometry(stack(100.0), w, np.asarray([65.0])).psi_deg)(jnp.asarray(wl)))
    np.testing.assert_allclose(a, b, rtol=1e-13)


def test_database_formula_page_k_table_on_a_concrete_grid():
    """A formula page with a tabulated k (refractiveindex.info "formula + tabulated k"): k
    sampled in numpy on a concrete grid equals ``np.interp`` of the page's k column."""
    from layerstack_jax._media.database import DatabaseFormula

    kw = (400.0, 600.0, 800.0)
    m = DatabaseFormula(kind=1, coefficients=(0.0, 1.0, 0.01), range_nm=(400.0, 800.0), k_wavelength_nm=kw,
                        k=(0.002, 0.001, 0.0), name="page")
    wl = np.array([400.0, 450.0, 600.0, 799.0, 800.0])
    got = m(wl)
    np.testing.assert_allclose(np.imag(np.asarray(got)), np.interp(wl, kw, [0.002, 0.001, 0.0]), rtol=1e-15, atol=1e-18)
    np.testing.assert_allclose(np.asarray(jax.jit(lambda x: m(x))(jnp.asarray(wl))), np.asarray(got), rtol=1e-14)


def test_batched_table_values_and_a_one_point_table():
    """Table values with a leading batch axis ``(*batch, table)`` interpolate along the last
    axis; a one-point table gives its value (as ``jnp.interp``)."""
    values = np.stack([TABLE_N, TABLE_K])
    got = interpolate_table(GRID, TABLE_WL, values)
    assert got.shape == (2, GRID.size)
    np.testing.assert_allclose(got, [np.interp(GRID, TABLE_WL, v) for v in values], rtol=1e-15, atol=1e-17)
    traced = jax.jit(lambda v: interpolate_table(GRID, TABLE_WL, v))(jnp.asarray(values))
    np.testing.assert_allclose(np.asarray(traced), got, rtol=1e-15, atol=1e-17)
    np.testing.assert_allclose(np.asarray(interpolate_table(np.array([500.0]), [500.0], [1.7])), [1.7])
