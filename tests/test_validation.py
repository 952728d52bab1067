"""Invalid input: a clear LayerstackError that names the offending field."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import layerstack_jax as ls

WL = jnp.array([450.0, 550.0])


def _raises(match, fn, *args, **kwargs):
    with pytest.raises(ls.LayerstackError, match=match) as info:
        fn(*args, **kwargs)
    return str(info.value)


def test_error_type_is_a_value_error():
    assert issubclass(ls.LayerstackError, ValueError)


@pytest.mark.parametrize("bad", [-1.0, -1e-9, np.array([10.0, -2.0])])
def test_negative_thickness(bad):
    msg = _raises("thickness", ls.Layer, 1.5, bad, name="varnish")
    assert "varnish" in msg and ">= 0" in msg


@pytest.mark.parametrize("bad", [math.nan, math.inf, np.array([10.0, np.nan])])
def test_nan_or_infinite_thickness(bad):
    msg = _raises("thickness", ls.Layer, 1.5, bad)
    assert "NaN" in msg or "infinite" in msg


def test_negative_extinction_coefficient():
    _raises("Index.k", ls.Index, 1.5, -0.1)
    _raises("Index.k", ls.Layer, complex(1.5, -0.1), 10.0)  # n + ik with k < 0
    _raises("Index.k", ls.Index, 1.5, np.array([0.0, -1e-3]))
    _raises("Cauchy.k", ls.Cauchy, 1.5, 0.01, 0.0, -0.2)
    _raises("Sellmeier.k", ls.Sellmeier, [1.0], [0.01], -0.2)
    _raises(r"silver\.k", ls.Tabulated, [400.0, 700.0], [0.1, 0.2], [-1.0, 3.0], name="silver")


def test_nan_index():
    _raises("Index.n", ls.Index, math.nan)


@pytest.mark.parametrize("bad", [1.2, -0.1, np.array([0.5, 1.0001]), math.nan])
def test_background_reflectance_outside_unit_interval(bad):
    _raises("rho_g", ls.LambertianBackground, 1.5, bad)


def test_tabulated_background_reflectance_outside_unit_interval_at_resolve():
    rho = ls.TabulatedSpectrum([400.0, 700.0], jnp.array([0.5, 1.5]))
    st = ls.Stack(1.0, [], ls.LambertianBackground(1.5, rho))
    ls.reflectance(st, jnp.array([450.0]), ls.Sphere(8.0))  # 0.67 there: fine
    _raises("rho_g", ls.reflectance, st, jnp.array([450.0, 650.0]), ls.Sphere(8.0))  # 1.33 at 650 nm


def test_alpha_on_a_coherent_layer():
    msg = _raises("alpha", ls.Layer, 1.5, 100.0, coherent=True, alpha=1e-5, name="film")
    assert "film" in msg and "incoherent" in msg


def test_negative_alpha():
    _raises("alpha", ls.Layer, 1.5, 1e4, coherent=False, alpha=-1e-5)


@pytest.mark.parametrize("ambient", [complex(1.0, 0.1), ls.Index(1.0, 0.01)])
def test_complex_ambient(ambient):
    _raises("ambient", ls.Stack, ambient, [], ls.Substrate(1.5))


def test_complex_background_index():
    _raises("exit", ls.Stack, 1.0, [], ls.LambertianBackground(complex(1.5, 0.1), 0.5))
    # an absorbing specular substrate is fine
    ls.Stack(1.0, [], ls.Substrate(complex(0.5, 3.0)))


@pytest.mark.parametrize(
    "text", ["foo", "", "sphere:8:xyz", "45/", "brdf:45", "specular", "specular:30:Q", "sphere:95", "120/0"]
)
def test_unknown_or_invalid_geometry_string(text):
    msg = _raises("geometry|quantity", ls.parse_geometry, text)
    assert repr(text) in msg or text in msg or "quantity" in msg


def test_valid_geometry_strings():
    assert ls.parse_geometry("sphere:8:sci") == ls.Sphere(8.0, "included")
    assert ls.parse_geometry("45/0") == ls.Directional(45.0, 0.0)
    assert ls.parse_geometry("brdf:45:0") == ls.BRDF(45.0, 0.0)
    assert ls.parse_geometry("specular:30:T") == ls.Specular(30.0, "T")


def test_geometry_objects_reject_bad_modes():
    _raises("specular", ls.Sphere, 8.0, "partly")
    _raises("quantity", ls.Specular, 10.0, "X")


def test_tabulated_out_of_range():
    mat = ls.Tabulated([400.0, 700.0], [1.5, 1.6], [0.0, 0.1], name="ink")
    st = ls.Stack(1.0, [ls.Layer(mat, 100.0)], ls.Substrate(1.5))
    msg = _raises("ink", ls.specular, st, jnp.array([300.0, 500.0]), 0.0)
    assert "outside" in msg and "400" in msg and "700" in msg
    _raises("ink", ls.specular, st, jnp.array([500.0, 800.0]), 0.0)
    # inside the range: fine, and it interpolates linearly
    out = ls.specular(st, jnp.array([400.0, 700.0]), angle_rad=0.0)
    assert out.R_front.shape == (2, 2)
    rho = ls.TabulatedSpectrum([400.0, 700.0], jnp.array([0.2, 0.3]), name="paint")
    bg = ls.Stack(1.0, [], ls.LambertianBackground(1.5, rho))
    _raises("paint", ls.reflectance, bg, jnp.array([380.0]), ls.Sphere(8.0))


def test_tabulated_out_of_range_inside_jit_raises():
    """Traced wavelengths: the range check runs inside the compiled function (equinox error)."""
    mat = ls.Tabulated([400.0, 700.0], [1.5, 1.6], name="ink")
    st = ls.Stack(1.0, [ls.Layer(mat, 100.0)], ls.Substrate(1.5))
    f = jax.jit(lambda wl: ls.specular(st, wl, angle_rad=0.0).R_front)
    f(jnp.array([450.0, 650.0]))  # fine
    with pytest.raises(Exception, match="outside the data range"):
        jax.block_until_ready(f(jnp.array([300.0, 650.0])))


def test_traced_checks_off_leaves_a_trial_point_to_its_caller():
    """``ls.traced_checks_off`` (for solvers whose line search may try a point outside the
    domain): the same traced check that raises under ``jit`` is not compiled in (a function
    traced inside the block keeps it off: JAX reuses its trace); concrete values are still
    checked."""
    mat = ls.Tabulated([400.0, 700.0], [1.5, 1.6], name="ink")
    st = ls.Stack(1.0, [ls.Layer(mat, 100.0)], ls.Substrate(1.5))
    def call(wl):
        return ls.specular(st, wl, angle_rad=0.0).R_front

    with ls.traced_checks_off():
        unchecked = jax.jit(lambda wl: call(wl))
        out = unchecked(jnp.array([300.0, 650.0]))  # outside the table: extrapolated, no error
    assert out.shape == (2, 2)
    assert unchecked(jnp.array([300.0, 650.0])).shape == (2, 2)  # its trace is reused outside the block
    with pytest.raises(Exception, match="outside the data range"):
        jax.block_until_ready(jax.jit(lambda wl: call(wl))(jnp.array([300.0, 650.0])))
    with ls.traced_checks_off():
        _raises("ink", call, jnp.array([300.0, 650.0]))


def test_bad_tables():
    _raises("strictly increasing", ls.Tabulated, [400.0, 400.0], [1.5, 1.6])
    _raises("column n", ls.Tabulated, [400.0, 500.0, 600.0], [1.5, 1.6])
    _raises("same length", ls.Sellmeier, [1.0, 0.2], [0.01])


def test_bad_wavelengths_side_and_layers():
    st = ls.Stack(1.0, [ls.Layer(1.5, 100.0)], ls.Substrate(1.5))
    _raises("wavelength", ls.specular, st, jnp.array([500.0, -1.0]), 0.0)
    _raises("wavelength", ls.specular, st, jnp.array([[500.0]]), 0.0)
    _raises("side", ls.diffuse, st, WL, "top")
    _raises(r"layers\[0\]", ls.Stack, 1.0, ["not a layer"], ls.Substrate(1.5))
    _raises("exit", ls.Stack, 1.0, [], 1.5)
