"""fit_batch never waits forever (issue 31).

The joint calibration objective with ρg(λ) free at 301 wavelengths hung in ``fit_batch`` at
0 % CPU: the vmapped solve put two batched LAPACK calls side by side in its loop body (the QR of
the damped Gauss–Newton system, the eigenvalues of the ``sigma_tol`` stopping test), and
jaxlib 0.10's CPU LAPACK kernels block an XLA pool thread while the parts of a batch run on the
same pool: with both pool threads of a 2-core machine blocked, nothing ran the parts. A batched
solve now runs fit by fit with the single fit's program (``fitting._compiled_fit.BLOCK``), and a
solve that stops using CPU is reported (``fitting._watchdog.wait_for``).

Every fit here passes ``stall_s``: were the deadlock back, the test would fail with the
watchdog's message instead of hanging the suite.
"""

from __future__ import annotations

import re
import threading
import time

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import fitting as ft
import layerstack_jax as ls
from fitting import _compiled_fit, _solver_options
from fitting._watchdog import wait_for

#: Seconds without CPU time after which a fit in these tests is declared stuck (well above any
#: pause of a running solve, well below a CI job's own timeout).
STALL = 60.0
SIGMA = 0.002
GEOMETRY = ls.Directional(45.0, 0.0)
THICKNESSES = np.array([10000.0, 20000.0, 30000.0, 40000.0])


def _stack(h, alpha, rho):
    return ls.Stack(1.0, [ls.Layer(1.52, h, coherent=False, alpha=alpha, name="varnish")],
                    ls.LambertianBackground(1.5, rho))


def _series(n_wl: int, alpha_basis=8, rho_g_basis="free"):
    """The issue's reproduction at ``n_wl`` wavelengths: ``(objective, clean spectra, clean
    background)`` — four varnish thicknesses over one background, 45°/0°, the first thickness
    known, the bare background fitted with them."""
    wl = np.linspace(400.0, 700.0, n_wl)
    alpha = 2e-6 * (1 + 0.5 * np.cos(np.linspace(0, 3, n_wl)))
    rho = 0.2 + 0.4 * np.linspace(0, 1, n_wl)
    clean = np.stack([np.asarray(ls.reflectance(_stack(h, jnp.asarray(alpha), jnp.asarray(rho)), wl, GEOMETRY))
                      for h in THICKNESSES])
    bare = np.asarray(ls.reflectance(ls.Stack(1.0, [], ls.LambertianBackground(1.5, jnp.asarray(rho))), wl, GEOMETRY))
    rng = np.random.default_rng(0)
    obj = ft.calibration_series(_stack(THICKNESSES[0], 1e-5, 0.5), wl, clean + SIGMA * rng.standard_normal(clean.shape),
                                GEOMETRY, layer="varnish", thicknesses=THICKNESSES * 0.8 + 1000, known=(0,),
                                alpha_basis=alpha_basis, rho_g_basis=rho_g_basis,
                                background=bare + SIGMA * rng.standard_normal(bare.shape), sigma=SIGMA)
    return obj, clean, bare


def _noisy(clean, bare, n_fits: int, seed: int = 1):
    rng = np.random.default_rng(seed)
    return [clean + SIGMA * rng.standard_normal((n_fits,) + clean.shape),
            bare + SIGMA * rng.standard_normal((n_fits,) + bare.shape)]


def _check_batch_equals_single_fits(obj, data, chunk_size: int, rtol: float = 1e-8):
    """fit_batch finishes (the watchdog would say otherwise), and each of its fits equals
    ``ft.fit`` on the same dataset: values, standard errors, status and steps."""
    n = data[0].shape[0]
    b = ft.fit_batch(obj, data, chunk_size=chunk_size, progress=False, stall_s=STALL)
    assert len(b) == n
    for i in range(n):
        r = ft.fit(obj, data=[d[i] for d in data])
        assert bool(b.converged[i]) == bool(r.converged), (i, b.reasons[i], r.reason)
        assert b.num_steps[i] == r.num_steps, i
        np.testing.assert_allclose(b.x[i], r.x, rtol=rtol, atol=0, err_msg=f"fit {i}")
        np.testing.assert_allclose(b.stderr[i], r.x_stderr, rtol=rtol, atol=0, err_msg=f"fit {i}")
    return b


# --------------------------------------------------------------------------- the cause
def _lapack_batch_dims(text: str) -> list[tuple[str, int]]:
    """``(target, batch dimensions)`` of each LAPACK custom call in a lowered program: its
    ``num_batch_dims`` attribute, or (without it) the first operand's rank minus 2."""
    calls = []
    for line in text.splitlines():
        m = re.search(r"custom_call @(lapack_\w+)\(", line)
        if not m:
            continue
        nb = re.search(r'num_batch_dims = "(\d+)"', line)
        if nb is None:
            shape = re.search(r":\s*\(tensor<([0-9x]*)x?[a-z]+\d*>", line)
            rank = len([d for d in shape.group(1).split("x") if d]) if shape else 2
            calls.append((m.group(1), rank - 2))
        else:
            calls.append((m.group(1), int(nb.group(1))))
    return calls


def test_batched_solve_holds_no_batched_lapack_call():
    """The compiled batch of fits calls LAPACK only on single matrices: no call that jaxlib's CPU
    kernels could split over the thread pool they are running on (the cause of the hang).
    The vmapped form (``block=4``) has such calls: the check can see them."""
    obj, _, _ = _series(31)
    o = _solver_options.SolverOptions()
    n = 4
    args = jax.tree.map(lambda a: jnp.broadcast_to(a, (n,) + a.shape), obj.args())
    y0 = jnp.broadcast_to(jnp.asarray(_solver_options.starting_point(obj, o, obj.layout.x0)), (n, obj.n_parameters))

    def calls(block):
        fn = _compiled_fit.compiled_fit(obj, o, batched=True, block=block)
        return _lapack_batch_dims(fn.lower(y0, args, obj.optics, _solver_options.NEVER).as_text())

    if jax.device_count() > 1:
        pytest.skip("several devices: the fits of a block are split over them")
    found = calls(_compiled_fit.BLOCK)
    if not found:
        pytest.skip("this jaxlib lowers no LAPACK custom call on the CPU")
    assert "lapack_dgeqrf_ffi" in {t for t, _ in found}  # the QR step (the stopping test: block QR or eigh)
    assert all(nb == 0 for _, nb in found), found
    assert any(nb > 0 for _, nb in calls(4))


# --------------------------------------------------------------------------- the reproduction
def test_issue_reproduction_four_fits_at_301_wavelengths():
    """The issue's reproduction (joint calibration objective, ρg(λ) free at 301 wavelengths,
    4 fits in one chunk): it finishes, each fit equal to ``ft.fit`` on its own data."""
    obj, clean, bare = _series(301)
    b = _check_batch_equals_single_fits(obj, _noisy(clean, bare, 4), chunk_size=4)
    assert b.converged.all()


def test_sixty_fits_of_a_31_wavelength_series():
    """60 fits of a 31-wavelength series with α on 8 B-splines and ρg free (the issue's second
    hanging configuration), in chunks of 16 (the last one padded)."""
    obj, clean, bare = _series(31)
    b = _check_batch_equals_single_fits(obj, _noisy(clean, bare, 60, seed=2), chunk_size=16)
    assert b.converged.mean() > 0.9


@pytest.mark.slow
def test_issue_reproduction_sixty_fits_at_301_wavelengths():
    obj, clean, bare = _series(301)
    b = _check_batch_equals_single_fits(obj, _noisy(clean, bare, 60, seed=3), chunk_size=16)
    assert b.converged.mean() > 0.9


# --------------------------------------------------------------------------- the sweep
SPECTRAL = {  # which spectral functions are free per wavelength (the other on 8 B-splines)
    "rho_g free": dict(alpha_basis=8, rho_g_basis="free"),
    "alpha free": dict(alpha_basis="free", rho_g_basis=8),
    "both free": dict(alpha_basis="free", rho_g_basis="free"),
}


@pytest.mark.parametrize("n_wl, spectral, n_fits, chunk", [
    (31, "alpha free", 3, 2),
    (61, "both free", 2, 2),
])
def test_sweep_default(n_wl, spectral, n_fits, chunk):
    obj, clean, bare = _series(n_wl, **SPECTRAL[spectral])
    _check_batch_equals_single_fits(obj, _noisy(clean, bare, n_fits, seed=n_wl), chunk_size=chunk)


@pytest.mark.slow
@pytest.mark.parametrize("n_fits, chunk", [(1, 1), (4, 4), (9, 4)])
@pytest.mark.parametrize("spectral", sorted(SPECTRAL))
@pytest.mark.parametrize("n_wl", [31, 101, 301])
def test_sweep_exhaustive(n_wl, spectral, n_fits, chunk):
    obj, clean, bare = _series(n_wl, **SPECTRAL[spectral])
    _check_batch_equals_single_fits(obj, _noisy(clean, bare, n_fits, seed=n_wl + n_fits), chunk_size=chunk)


# --------------------------------------------------------------------------- the watchdog
class _Pending:
    """Stands in for a JAX array whose computation runs elsewhere (a program with host callbacks
    cannot: JAX runs it while dispatching): ready once ``event`` is set, meanwhile
    ``burn`` keeps a thread of this process busy (a running computation) or not (a stuck one)."""

    def __init__(self, event: threading.Event, burn: bool = False):
        self.event = event
        if burn:
            threading.Thread(target=self._burn, daemon=True).start()

    def _burn(self):
        while not self.event.is_set():
            sum(range(1000))

    def is_ready(self):
        return self.event.is_set()

    def devices(self):
        return {jax.devices("cpu")[0]}

    def __array__(self, dtype=None, copy=None):
        return np.ones(3)


def test_watchdog_names_a_computation_that_has_stopped():
    event = threading.Event()
    t = time.perf_counter()
    try:
        with pytest.raises(ls.LayerstackError, match=r"fit_batch: chunk 1 of 1: the compiled computation has stopped: "
                                                     r"the process has used no CPU time for \d+ s.*cannot finish"):
            wait_for({"x": _Pending(event)}, what="fit_batch: chunk 1 of 1", stall_s=1.0)
        assert time.perf_counter() - t < 30
    finally:
        event.set()


def test_watchdog_waits_for_a_slow_computation_and_keeps_the_time_limit():
    event = threading.Event()
    threading.Timer(2.5, event.set).start()
    # running (this process uses CPU) for 2.5 s, 5 times the stall window: slow, not stuck
    out = wait_for({"x": _Pending(event, burn=True), "y": jnp.zeros(2)}, what="slow", stall_s=0.5)
    np.testing.assert_array_equal(out["x"], np.ones(3))
    np.testing.assert_array_equal(out["y"], np.zeros(2))
    held = threading.Event()
    try:
        with pytest.raises(ls.LayerstackError, match="late: not finished within the time limit"):
            wait_for(_Pending(held, burn=True), what="late", stall_s=None, deadline=time.monotonic() + 0.5)
    finally:
        held.set()


def test_fit_batch_reports_a_stuck_chunk(monkeypatch):
    """fit_batch waits through the watchdog: a chunk whose computation stops raises, naming it
    and what was done, instead of waiting."""
    obj, clean, bare = _series(11)
    event = threading.Event()
    real = _compiled_fit.compiled_fit

    def stuck(objective, o, batched, block=_compiled_fit.BLOCK):
        fn = real(objective, o, batched, block)
        return lambda *a: fn(*a)._replace(x=_Pending(event))

    monkeypatch.setattr("fitting._batch.compiled_fit", stuck)
    try:
        with pytest.raises(ls.LayerstackError, match=r"fit_batch: chunk 1 of 2 \(2 fits\).*has stopped.*0 of 2 chunks"):
            ft.fit_batch(obj, _noisy(clean, bare, 4), chunk_size=2, progress=False, stall_s=1.0)
    finally:
        event.set()


@pytest.mark.parametrize("name, value", [("timeout_s", 0), ("stall_s", -1.0), ("timeout_s", "10")])
def test_fit_batch_refuses_bad_time_limits(name, value):
    obj, clean, bare = _series(11)
    with pytest.raises(ls.LayerstackError, match=name):
        ft.fit_batch(obj, _noisy(clean, bare, 2), progress=False, **{name: value})
