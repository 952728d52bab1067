"""One compiled program per public call (``layerstack_jax._base.programs``), and the unit slips that
used to end in a silent wrong spectrum (issue "the first hour").

Compilations are counted with JAX's own compile events (``/jax/core/compile/backend_compile_duration``,
one per XLA program compiled), not with the library's bookkeeping. The expected values of the
compiled calls are the op-by-op evaluation of the same function (``__wrapped_program__``) and, for
the unit slips, the spectra of the intended units.
"""

from __future__ import annotations

import contextlib
import functools
import re
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import layerstack_jax as ls

WL = np.linspace(400.0, 700.0, 31)


@contextlib.contextmanager
def counted_compilations():
    """Yield a list whose length is the number of XLA programs compiled inside the block."""
    events = []

    def listener(event, duration, **kwargs):
        if event == "/jax/core/compile/backend_compile_duration":
            events.append(duration)

    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        yield events
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)


def _varnish(h=30_000.0, alpha=2e-6, rho=0.6, n=1.54, layers=1):
    return ls.Stack(1.0, [ls.Layer(n, h, coherent=False, alpha=alpha, name=f"varnish{i}") for i in range(layers)],
                    ls.LambertianBackground(1.5, rho))


def _film(d=120.0, n=1.46):
    return ls.Stack(1.0, [ls.Layer(n, d, coherent=True, name="film")], ls.Substrate(3.9 + 0.02j))


# each case: a public call on a model structure used nowhere else in this module, then the same
# call with new values everywhere (indices, thicknesses, α, ρg, angles)
CASES = {
    "reflectance 45/0": (lambda v: ls.reflectance(_varnish(3e4 * v, 2e-6 * v, 0.5 * v, layers=2), WL,
                                                  ls.Directional(40.0 + v, 3.0 * v))),
    "reflectance sphere": (lambda v: ls.reflectance(_varnish(2e4 * v, 1e-6 * v, 0.4 * v, layers=3), WL,
                                                    ls.Sphere(7.0 + v, "included"))),
    "specular": (lambda v: ls.specular(_film(100.0 * v, 1.4 + 0.1 * v), WL, 20.0 + 10 * v).R_front),
    "ellipsometry": (lambda v: ls.ellipsometry(_film(90.0 * v, 1.45 + 0.01 * v), WL, 60.0 + v).psi_deg),
    "colour": (lambda v: _colour_space().Lab(np.full(41, 0.3 * v))),
}


@functools.cache
def _colour_space():
    return ls.ColourSpace(np.linspace(380.0, 780.0, 41))


@pytest.mark.parametrize("name", CASES)
def test_one_program_per_call_structure_and_none_for_new_values(name):
    call = CASES[name]
    _colour_space()  # built once (its tables are not the call under test)
    with counted_compilations() as first:
        a = np.asarray(call(1.0))
    with counted_compilations() as again:
        b = np.asarray(call(1.37))
    assert len(first) == 1, f"{name}: {len(first)} XLA programs compiled by the first call"
    assert len(again) == 0, f"{name}: {len(again)} programs compiled for new values"
    assert np.all(np.isfinite(a)) and np.all(np.isfinite(b)) and not np.allclose(a, b)


def test_compiled_call_equals_the_op_by_op_evaluation():
    stack, g = _varnish(layers=2), ls.Sphere(8.0, "excluded")
    op_by_op = ls.reflectance.__wrapped_program__(stack, WL, g)
    np.testing.assert_allclose(ls.reflectance(stack, WL, g), op_by_op, rtol=1e-13, atol=0)
    r = ls.specular(_film(), WL, 35.0)
    r0 = ls.specular.__wrapped_program__(_film(), WL, 35.0)
    for x, y in zip(r, r0):
        np.testing.assert_allclose(x, y, rtol=1e-12, atol=1e-15)


def test_invalid_value_raises_the_eager_error_with_its_values():
    # values the constructors cannot see: the grid, and a spectrum given as an array on it
    bad_grid = np.where(WL == WL[3], -1.0, WL)
    with pytest.raises(ls.LayerstackError, match=r"wavelength_nm \(nm\) must be > 0.*got range \[-1\.0, 700\.0\]"):
        ls.reflectance(_varnish(), bad_grid, ls.Directional(45.0, 0.0))
    rho = np.full(WL.size, 0.5)
    rho[7] = 1.2
    with pytest.raises(ls.LayerstackError, match=r"rho_g must lie in \[0, 1\], got range \[0\.5, 1\.2\]"):
        ls.reflectance(_varnish(rho=rho), WL, ls.Directional(45.0, 0.0))
    # the same structure with valid values still runs the compiled program
    with counted_compilations() as events:
        assert np.all(np.isfinite(np.asarray(ls.reflectance(_varnish(rho=0.7), WL, ls.Directional(45.0, 0.0)))))
    assert len(events) == 0


def test_inside_a_users_jit_the_call_is_part_of_their_program():
    f = jax.jit(lambda h: ls.reflectance(_varnish(h=h), WL, ls.Directional(45.0, 0.0)))
    np.testing.assert_allclose(f(25_000.0), ls.reflectance(_varnish(h=25_000.0), WL, ls.Directional(45.0, 0.0)),
                               rtol=1e-12)
    g = jax.grad(lambda h: jnp.sum(ls.reflectance(_varnish(h=h), WL, ls.Sphere(8.0))))(25_000.0)
    assert np.isfinite(float(g)) and float(g) != 0.0


# ------------------------------------------------ unit slips: a warning naming the field and the unit

def _warnings_of(fn):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fn()
        jax.effects_barrier()
    return [str(w.message) for w in caught if issubclass(w.category, ls.LayerstackWarning)]


SLIPS = {
    # a 30 µm varnish given as 30: a 30 nm "thick" layer is no layer at all
    "thickness in µm": (lambda x: _varnish(h=x), 30.0, 30_000.0, r"varnish0\): thickness \(nm\) 30\.0.*µm given"),
    # α = 20/cm given as 20 (1/nm): opaque, a spectrum of the front reflection only
    "alpha in 1/cm": (lambda x: _varnish(alpha=x), 20.0, 20.0e-7, r"varnish0\): alpha \(1/nm\) 20\.0.*1/cm given"),
}


@pytest.mark.parametrize("name", SLIPS)
def test_unit_slips_warn_eagerly_and_under_jit(name):
    build, slip, meant, pattern = SLIPS[name]
    geometry = ls.Directional(45.0, 0.0)
    eager = _warnings_of(lambda: ls.reflectance(build(slip), WL, geometry))
    assert any(re.search(pattern, m) for m in eager), eager
    jitted = jax.jit(lambda x: ls.reflectance(build(x), WL, geometry))
    under_jit = _warnings_of(lambda: jitted(slip).block_until_ready())
    assert any(re.search(pattern, m) for m in under_jit), under_jit
    # the intended unit: no warning, and a spectrum unlike the slip's
    assert _warnings_of(lambda: ls.reflectance(build(meant), WL, geometry)) == []
    assert _warnings_of(lambda: jitted(meant).block_until_ready()) == []
    assert np.max(np.abs(np.asarray(ls.reflectance(build(meant), WL, geometry))
                         - np.asarray(ls.reflectance(build(slip), WL, geometry)))) > 0.01


def test_under_vmap_one_call_back_warns_with_the_first_flagged_draw():
    """A vmapped (and nested-vmapped, differentiated) batch warns once per call, naming the first
    flagged element's value; the compiled program holds one call back, not one per element (JAX
    unrolls a vmapped ``jax.debug.callback``: 2000 draws compiled 2000 call backs)."""
    geometry = ls.Directional(45.0, 0.0)
    h = np.full(400, 25_000.0)
    h[[137, 300]] = [30.0, 40.0]  # two draws given in µm
    one = jax.jit(lambda x: ls.reflectance(_varnish(h=x), WL, geometry))
    caught = _warnings_of(lambda: jax.vmap(one)(h).block_until_ready())
    assert len(caught) == 1 and re.search(r"thickness \(nm\) 30\.0.*µm given", caught[0]), caught
    text = jax.jit(jax.vmap(one)).lower(h).as_text()
    assert text.count("callback") <= 4, "one call back per element was compiled"
    nested = jax.vmap(jax.vmap(jax.grad(lambda x: jnp.sum(one(x)))))
    caught = _warnings_of(lambda: nested(h.reshape(20, 20)).block_until_ready())
    assert len(caught) == 1 and re.search(r"thickness \(nm\) 30\.0", caught[0]), caught
    assert _warnings_of(lambda: jax.vmap(one)(np.full(400, 25_000.0)).block_until_ready()) == []


def test_radian_angles_in_geometry_spellings_warn():
    with pytest.warns(ls.LayerstackWarning, match=r"specular:1\.2217.*radians given"):
        ls.parse_geometry("specular:1.2217")
    with pytest.warns(ls.LayerstackWarning, match=r"ellipsometry:1\.2217:psi.*radians given"):
        ls.parse_geometry("ellipsometry:1.2217:psi")
    for text in ("specular:30", "45/0", "sphere:8:sce", "brdf:45:0", "ellipsometry:70:psi", "sphere:8:sce:cone=5"):
        assert _warnings_of(lambda: ls.parse_geometry(text)) == [], text


def test_thin_incoherent_layer_warning_spares_zero_padding_and_real_thick_layers():
    for h in (0.0, 1_000.0, 30_000.0):
        assert _warnings_of(lambda: ls.reflectance(_varnish(h=h), WL, ls.Sphere(8.0))) == [], h


def test_compilation_cache_dir_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.setenv("LAYERSTACK_CACHE_DIR", str(tmp_path))
    assert ls.compilation_cache_dir() == str(tmp_path)
    monkeypatch.setenv("LAYERSTACK_CACHE_DIR", "")
    assert ls.compilation_cache_dir() == ""
    monkeypatch.delenv("LAYERSTACK_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert ls.compilation_cache_dir() == str(tmp_path / "layerstack" / "xla")
