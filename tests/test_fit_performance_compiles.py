"""What a fit compiles (issue 15): one program per model structure, reused.

* The ψ/Δ datasets of an ideal ellipsometer are read by one :func:`layerstack_jax.ellipsometry`
  over their angles (``Objective.predict``): the same numbers as each dataset's own
  ``geometry.measure``, bit for bit, compiled.
* ``fit`` compiles its solver once: a second fit of the same objective on new data, and a
  multi-start (solved start after start by the same compiled solver), compile nothing.
* The multi-start give-up rule (:func:`fitting._multistart.give_up_rule`) ends hopeless starts; the
  chosen start is the single fit's.

Compilations are counted with JAX's own compile events (``jax.monitoring``), not timed.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import fitting as ft
import layerstack_jax as ls
from fitting import _compiled_fit, _fit_jit, _multistart, _solver_options
from fitting._status import ABANDONED, STATUS
from _helpers import compiles

WL = np.linspace(400.0, 800.0, 60)
ANGLES = (60.0, 70.0)
TRUTH = (120.0, 1.55, 0.008)  # film thickness nm, Cauchy A, B (µm²)
SIGMA = 0.02



def _stack(d, A, B):
    film = ls.Layer(ls.Cauchy(A, B), d, name="film")
    oxide = ls.Layer(1.46, 2.0, name="oxide")
    return ls.Stack(1.0, [film, oxide], ls.Substrate(complex(3.9, 0.02)))


def _data(seed):
    rng = np.random.default_rng(seed)
    e = ls.ellipsometry(_stack(*TRUTH), WL, np.asarray(ANGLES))
    psi = np.asarray(e.psi_deg) + SIGMA * rng.standard_normal((len(ANGLES), WL.size))
    delta = np.asarray(e.delta_deg) + SIGMA * rng.standard_normal((len(ANGLES), WL.size))
    return [a[None] for i in range(len(ANGLES)) for a in (psi[i], delta[i])]


def _objective():
    data = _data(0)
    datasets = [ft.Dataset(ls.Ellipsometric(a, q), data[2 * i + k], sigma=SIGMA)
                for i, a in enumerate(ANGLES) for k, q in enumerate(("psi", "delta"))]
    params = [ft.thickness("film", lower=20.0, upper=300.0), ft.dispersion("film", "A"), ft.dispersion("film", "B")]
    return ft.Objective(_stack(100.0, 1.50, 0.005), WL, datasets, params)


@pytest.fixture(scope="module")
def objective():
    return _objective()


def test_shared_ellipsometer_reading_equals_each_geometry():
    """Ideal ellipsometer datasets at repeated and distinct angles, every quantity: the shared
    reading of ``predict`` equals each dataset's own ``measure``, compiled, bit for bit — values
    and forward-mode Jacobian."""
    quantities = ("psi", "delta", "N", "C", "S", "rho_re", "rho_im", "depolarization")
    geoms = [ls.Ellipsometric(a, q) for a in (55.0, 70.0) for q in quantities] + [ls.Ellipsometric(62.5, "psi")]
    zeros = np.zeros((1, WL.size))
    obj = ft.Objective(_stack(*TRUTH), WL, [ft.Dataset(g, zeros) for g in geoms],
                       [ft.thickness("film"), ft.dispersion("film", "A"), ft.dispersion("film", "B")])
    x = jnp.asarray([118.0, 1.56, 0.0075])

    def own(v):
        st = obj.stack_for(v)
        return jnp.concatenate([g.measure(st, WL).ravel() for g in geoms])

    def shared(v):
        return jnp.concatenate([m.ravel() for m in obj.predict(v)])

    np.testing.assert_array_equal(np.asarray(jax.jit(shared)(x)), np.asarray(jax.jit(own)(x)))
    np.testing.assert_array_equal(np.asarray(jax.jit(jax.jacfwd(shared))(x)), np.asarray(jax.jit(jax.jacfwd(own))(x)))


def test_second_fit_and_multistart_compile_nothing(objective):
    first, n_first = compiles(ft.fit, objective)
    assert first.converged and n_first >= 1
    # a further fit of the same structure on new data: the cached solver, nothing compiled
    again, n_again = compiles(ft.fit, objective, data=_data(1))
    assert again.converged and n_again == 0, n_again
    assert np.all(np.abs(again.x - np.asarray(TRUTH)) < 5 * again.x_stderr)
    # a multi-start: the same compiled solver, start after start
    multi, n_multi = compiles(ft.fit, objective, starts=6, seed=3, progress=False)
    assert n_multi == 0, n_multi
    assert multi.starts == 6 and multi.starts_converged >= 1
    # the objective's own start found the minimum: it is the one reported, as by the single fit
    np.testing.assert_allclose(multi.x, first.x, rtol=1e-12)
    assert multi.num_steps == first.num_steps and multi.report().count("multi-start") == 1


def test_give_up_rule_and_abandoned_starts(objective):
    assert _multistart.give_up_rule(np.inf, 0) == _solver_options.NEVER
    assert _multistart.give_up_rule(50.0, 11) == (33, 500.0)
    assert _multistart.give_up_rule(50.0, 4) == (_multistart.GIVE_UP_MIN_STEPS, 500.0)
    assert ABANDONED in STATUS and "given up" in STATUS[ABANDONED]
    o = _solver_options.SolverOptions("lm", max_steps=256)
    fn = _compiled_fit.compiled_fit(objective, o, batched=False)
    y0 = _solver_options.starting_point(objective, o, objective.layout.x0)
    plain = fn(y0, objective.args(), objective.optics)
    cost = float(_multistart._cost(jax.tree.map(np.asarray, plain)))
    # a rule that cannot fire leaves the fit as it was; one whose cost limit lies below the
    # optimum ends the solve at its step count, marked abandoned
    same = fn(y0, objective.args(), objective.optics, (1000, 10.0 * cost))
    np.testing.assert_array_equal(np.asarray(same.x), np.asarray(plain.x))
    assert int(same.status) == int(plain.status) == 0
    cut = fn(y0, objective.args(), objective.optics, (3, 0.5 * cost))
    assert int(cut.status) == ABANDONED and int(cut.num_steps) == 3


def test_shared_ellipsometer_reading_only_where_it_is_ellipsometry():
    """The objective reads several ideal ellipsometer datasets of one stack with one
    ``ellipsometry()`` — and only those: a transmission ellipsometer or a stack with a thick
    substrate (depolarizing backside) is read by each dataset's own ``measure`` (a shared
    reflection call gave transmission datasets reflection numbers, and refused thick stacks)."""
    import layerstack_jax as ls

    wl = np.linspace(400.0, 700.0, 7)
    film = ls.Stack(1.0, [ls.Layer(ls.Cauchy(1.46, 0.004), 120.0, name="film")], ls.Substrate(1.5))
    slide = ls.Stack(1.0, [ls.Layer(1.6, 80.0, name="film"), ls.Layer(1.5, 1e6, coherent=False, name="glass")],
                     ls.Substrate(1.0))
    cases = [(film, "reflection"), (film, "transmission"), (slide, "reflection"), (slide, "transmission")]
    for stack, mode in cases:
        gs = [ls.Ellipsometric(a, q, mode=mode) for a in (50.0, 60.0) for q in ("psi", "delta")]
        expect = [np.asarray(g.measure(stack, wl)) for g in gs]
        obj = ft.Objective(stack, wl, [ft.Dataset(g, y, sigma=0.01) for g, y in zip(gs, expect)],
                           [ft.thickness("film")])
        got = obj.predict(obj.layout.x0)
        for g, y, m in zip(gs, expect, got):
            np.testing.assert_allclose(np.asarray(m)[0], y, rtol=1e-12, atol=1e-12, err_msg=f"{g.label} {mode}")
        together = ls.shared_readings(gs, stack)
        assert bool(together.angles) == (stack is film and mode == "reflection")  # one ellipsometry() over both angles
        assert together.indices == frozenset(range(4))  # else one reading() per instrument: shared all the same


def test_compiled_fit_of_table_materials_holds_no_host_callback():
    """The range checks of database and tabulated materials are off inside the solver (the
    objective checked its grid against every table when it was built): the compiled fit holds
    no host callback, so JAX can keep it in its persistent compilation cache (a program with a
    callback is never written there) — and it has two runtime branches less to compile."""
    wl = np.linspace(400.0, 800.0, 9)
    ink = ls.Tabulated([300.0, 900.0], [1.55, 1.50], name="ink")

    def stack(d):
        return ls.Stack(1.0, [ls.Layer(ink, d, name="film"), ls.Layer(ls.material("SiO2", "Malitson"), 2.0)],
                        ls.Substrate(ls.material("Si", "Aspnes")))

    e = ls.ellipsometry(stack(120.0), wl, np.asarray([60.0]))
    obj = ft.Objective(stack(100.0), wl, [ft.Dataset(ls.Ellipsometric(60.0, "psi"), np.asarray(e.psi_deg)[0], sigma=0.01)],
                       [ft.thickness("film", lower=20.0, upper=300.0)])
    o = _solver_options.SolverOptions()
    fn = _compiled_fit.compiled_fit(obj, o, batched=False)
    y0 = _solver_options.starting_point(obj, o, obj.layout.x0)
    jaxpr = str(jax.make_jaxpr(fn.jitted)(y0, obj.args(), obj.optics, _solver_options.NEVER))
    assert "callback" not in jaxpr
    assert float(np.squeeze(ft.fit(obj).values["thickness[film]"])) == pytest.approx(120.0, rel=1e-8)
    # outside the solver the same materials are still checked under jit
    f = jax.jit(lambda w: ls.ellipsometry(stack(100.0), w, np.asarray([60.0])).psi_deg)
    with pytest.raises(Exception, match="outside the data range"):
        jax.block_until_ready(f(jnp.asarray([150.0, 500.0])))


@pytest.mark.parametrize("method", ["lm", "gauss-newton", "dogleg"])
def test_compiling_a_fit_traces_the_model_once(method, monkeypatch):
    """Compiling a least-squares fit traces the model (``Objective.predict``, and with it the
    forward-mode Jacobian around it) once: optimistix calls the residual function in a
    structure pass and again in its loop, under different abstract-mesh contexts, which made
    JAX's tracing cache miss and the model — most of a fit's tracing time — be traced twice
    (``fitting._fit_functions._traced_once``). Counted in Python calls of ``predict``, for a single fit
    and a batched one; a second fit traces nothing."""
    data = _data(0)[:1]
    obj = ft.Objective(_stack(115.0, 1.54, TRUTH[2]), WL, [ft.Dataset(ls.Ellipsometric(ANGLES[0], "psi"), data[0], sigma=SIGMA)],
                       [ft.thickness("film", lower=20.0, upper=300.0), ft.dispersion("film", "A")])
    calls = []
    predict = ft.Objective.predict
    monkeypatch.setattr(ft.Objective, "predict", lambda self, *a, **k: calls.append(1) or predict(self, *a, **k))
    assert ft.fit(obj, method=method).converged
    assert len(calls) == 1, len(calls)
    ft.fit(obj, method=method)
    assert len(calls) == 1, len(calls)
    del calls[:]
    batch = ft.fit_batch(obj, np.concatenate([data[0], _data(1)[0]]), method=method, progress=False)
    assert np.all(np.asarray(batch.converged))
    assert len(calls) == 1, len(calls)


def test_single_fit_compiler_options(monkeypatch):
    """A single fit's programs are compiled on the CPU with
    :data:`fitting._fit_jit.SINGLE_FIT_COMPILER_OPTIONS` (XLA's classic fusion emitters: about
    half the compile time of a fit): known to this XLA, and the fit is the one XLA's default
    options give (values to 1e-9, standard errors to 1e-6). An option the XLA does not know, a GPU
    backend, or the same option in the user's ``XLA_FLAGS`` leave XLA's defaults."""
    probe = _fit_jit._compiler_options
    probe.cache_clear()
    try:
        assert probe("cpu") == _fit_jit.SINGLE_FIT_COMPILER_OPTIONS
        assert probe("gpu") is None
        fresh = _objective()
        with_options = ft.fit(fresh)
        (fn,) = [v for k, v in fresh.cache.items() if k[0] == "fit"]
        assert fn.jitted.top is not fn.jitted.jitted  # the single fit was compiled with the options
        monkeypatch.setattr(_fit_jit, "_compiler_options", lambda backend: None)
        default = ft.fit(_objective())
        assert with_options.converged and default.converged
        np.testing.assert_allclose(np.asarray(with_options.x), np.asarray(default.x), rtol=1e-9)
        np.testing.assert_allclose(np.asarray(with_options.x_stderr), np.asarray(default.x_stderr), rtol=1e-6)
        monkeypatch.setattr(_fit_jit, "_compiler_options", probe)
        monkeypatch.setenv("XLA_FLAGS", "--xla_cpu_use_fusion_emitters=true")
        probe.cache_clear()
        assert probe("cpu") is None
        monkeypatch.delenv("XLA_FLAGS")
        monkeypatch.setattr(_fit_jit, "SINGLE_FIT_COMPILER_OPTIONS", {"xla_cpu_no_such_option_here": False})
        probe.cache_clear()
        assert probe("cpu") is None
    finally:
        probe.cache_clear()


def test_readings_of_one_instrument_at_several_angles_share_one_reading(monkeypatch):
    """Ellipsometer readings that are not ``ellipsometry()``'s — a thick substrate with its
    backside, an instrument with a bandwidth — are read with one ``reading()`` over the angles of
    each instrument (``layerstack_jax.shared_readings``), not one per dataset: the same
    values as each dataset's own ``measure`` (to 1e-12), three readings instead of fifteen here.
    A dataset whose instrument differs (an angle offset) keeps its own reading."""
    wl = np.linspace(420.0, 780.0, 19)
    stack = ls.Stack(1.0, [ls.Layer(ls.Cauchy(1.9, 0.01), 150.0, name="film"),
                           ls.Layer(1.515, 1.0e6, coherent=False, name="glass")], ls.Substrate(1.0))
    geometries = [ls.Ellipsometric(a, q) for a in (50.0, 60.0, 70.0) for q in ("psi", "delta", "depolarization", "rho_re")]
    geometries += [ls.Ellipsometric(a, "N", bandwidth_nm=5.0) for a in (55.0, 65.0)]
    geometries += [ls.Ellipsometric(65.0, "C", angle_offset_deg=0.2)]
    data = [np.zeros((1, wl.size)) for _ in geometries]
    obj = ft.Objective(stack, wl, [ft.Dataset(g, y) for g, y in zip(geometries, data)], [ft.thickness("film")])
    calls = []
    reading = ls.Ellipsometric.reading
    monkeypatch.setattr(ls.Ellipsometric, "reading", lambda self, *a, **k: calls.append(1) or reading(self, *a, **k))
    predicted = jax.jit(lambda x: obj.predict(x, obj.optics))(jnp.asarray([150.0]))
    assert len(calls) == 3, len(calls)
    # a fitted angle offset shared by the datasets of three angles (fitting.instrument): still one reading
    offset = ft.Objective(stack, wl, [ft.Dataset(g, y) for g, y in zip(geometries[:12], data[:12])],
                          [ft.thickness("film"), ft.instrument("angle_offset_deg", value=0.1)])
    del calls[:]
    with_offset = jax.jit(lambda x: offset.predict(x, offset.optics))(jnp.asarray([150.0, 0.1]))
    assert len(calls) == 1, len(calls)
    monkeypatch.setattr(ls.Ellipsometric, "reading", reading)
    own = jax.jit(lambda st: [g.measure(st, wl) for g in geometries])(stack)  # each dataset's own reading
    for p, q in zip(predicted, own):
        np.testing.assert_allclose(np.asarray(p)[0], np.asarray(q), rtol=1e-12, atol=1e-13)
    shifted = [ls.Ellipsometric(g.angle_deg, g.quantity, angle_offset_deg=0.1) for g in geometries[:12]]
    own = jax.jit(lambda st: [g.measure(st, wl) for g in shifted])(stack)
    for p, q in zip(with_offset, own):
        np.testing.assert_allclose(np.asarray(p)[0], np.asarray(q), rtol=1e-12, atol=1e-13)
