"""fitting/_structured.py: block-structured least squares for spectral parameters free per wavelength.

References, independent of the structured code: the dense path of the same library (the full
Jacobian by ``jax.jacfwd`` of the objective's residuals, QR steps, the SVD covariance), a NumPy
re-derivation of the covariance written here (:math:`(J^\\top J)^{-1}` from the full Jacobian,
``np.linalg.inv``), scipy's ``least_squares`` on the same residuals for the minimum, and the
binomial expectation for noisy replicates (95.4 % within ±2σ). The "measurements" are made by the
public forward model with the true values.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import fitting as ft
import layerstack_jax as ls
from fitting import _fit_functions, _structured
from layerstack_jax import LayerstackError

SIGMA = 0.002


def _rel(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-300)))


def _cov_rel(a, b):
    """Largest |ΔC_ij| / sqrt(C_ii C_jj): covariance agreement relative to its own scale."""
    d = np.sqrt(np.diag(b))
    return float(np.max(np.abs(a - b) / np.outer(d, d)))


# ----------------------------------------------------------------------------- problems
def slab_problem(n_wl=24):
    """Two thick free-standing slabs (one thickness known, the other fitted), R and T at normal
    incidence: n(λ) and α(λ) both free per wavelength (two spectral blocks), one global."""
    wl = np.linspace(420.0, 680.0, n_wl)
    n_true = 1.50 + 0.01 * np.cos(np.linspace(0, 3, n_wl))
    a_true = 3e-6 * (1 + 0.5 * np.sin(np.linspace(0, 4, n_wl)))
    h = np.array([200_000.0, 350_000.0])

    def stack(hh, n, a):
        return ls.Stack(1.0, [ls.Layer(ls.Index(n), hh, coherent=False, alpha=a, name="slab")], ls.Substrate(1.0))

    gR, gT = ls.Specular(0.0, "R"), ls.Specular(0.0, "T")
    rng = np.random.default_rng(3)
    data = [np.stack([np.asarray(ls.reflectance(stack(x, jnp.asarray(n_true), jnp.asarray(a_true)), wl, g)) for x in h])
            for g in (gR, gT)]
    data = [d + SIGMA * rng.standard_normal(d.shape) for d in data]
    params = [ft.thickness("slab", value=[200_000.0, 330_000.0], per_sample=True, fixed=np.array([True, False])),
              ft.index_n("slab", basis="free", value=np.full(n_wl, 1.48)),
              ft.alpha("slab", basis="free", value=np.full(n_wl, 2e-6))]
    obj = ft.Objective(stack(h[0], np.full(n_wl, 1.48), 2e-6), wl, [ft.Dataset(gR, data[0], sigma=SIGMA),
                                                                   ft.Dataset(gT, data[1], sigma=SIGMA)],
                       params, n_samples=2)
    return obj


def _calibration(n_wl, alpha_basis, seed=0):
    wl = np.linspace(400.0, 700.0, n_wl)
    H = np.array([10000.0, 20000.0, 30000.0, 40000.0])
    alpha = 2e-5 * (1 + 0.5 * np.cos(np.linspace(0, 3, n_wl)))
    rho = 0.2 + 0.4 * np.linspace(0, 1, n_wl)

    def st(h, a, r):
        return ls.Stack(1.0, [ls.Layer(1.52, h, coherent=False, alpha=a, name="varnish")],
                        ls.LambertianBackground(1.5, r))

    g = ls.Directional(45.0, 0.0)
    clean = np.stack([np.asarray(ls.reflectance(st(h, jnp.asarray(alpha), jnp.asarray(rho)), wl, g)) for h in H])
    bare = np.asarray(ls.reflectance(ls.Stack(1.0, [], ls.LambertianBackground(1.5, jnp.asarray(rho))), wl, g))
    rng = np.random.default_rng(seed)
    obj = ft.calibration_series(st(H[0], 1e-5, 0.5), wl, clean + SIGMA * rng.standard_normal(clean.shape), g,
                                layer="varnish", thicknesses=np.r_[H[0], H[1:] * 0.8 + 1000], known=(0,),
                                alpha_basis=alpha_basis,
                                rho_g_basis="free", background=bare + SIGMA * rng.standard_normal(bare.shape),
                                sigma=SIGMA)
    truth = np.concatenate([H[1:], alpha if isinstance(alpha_basis, str) else [], rho])
    return obj, clean, bare, truth


@pytest.fixture(scope="module")
def slab():
    return slab_problem()


@pytest.fixture(scope="module")
def calibration():
    """ρg(λ) free at 31 wavelengths, α on 8 B-splines, 3 thicknesses: 42 parameters, 11 globals."""
    obj, clean, bare, _ = _calibration(31, 8)
    return obj, clean, bare


# ----------------------------------------------------------------------------- the Jacobian
def test_structure_found_and_compressed_jacobian_is_the_full_one(slab):
    st = _fit_functions.structure_for(slab, "structured", "lm")
    assert (st.b, st.g, st.k, st.W) == (2, 1, 4, 24)  # n, α per wavelength; one thickness; 2 datasets × 2 samples
    x = slab.layout.x0 * 1.01
    scale = jnp.asarray(slab.layout.scale)
    args = slab.args()
    fn = _structured.structured_statistics_function(slab, st, _fit_functions._residuals_and_parts(slab))
    J = fn(jnp.asarray(x), args, slab.optics)[3]
    assert np.shape(J.K) == (st.M, 3)  # three tangents for 49 parameters
    full = np.asarray(jax.jacfwd(lambda z: slab.residuals(z * scale, args, slab.optics))(jnp.asarray(x) / scale))
    np.testing.assert_allclose(J.dense(), full, rtol=1e-12, atol=1e-14 * np.abs(full).max())


def test_the_structure_check_refuses_a_model_that_mixes_wavelengths(slab):
    st, _ = _structured.find_structure(slab)
    parts = _fit_functions._residuals_and_parts(slab)

    def smeared(z, args, optics):  # a neighbour's value leaks into each reading (a bandwidth)
        flat, by = parts(z, args, optics)
        return flat + 1e-3 * jnp.roll(flat, 1), by

    ok, why = _structured.verify_structure(slab, st, smeared)
    assert not ok and "other wavelengths" in why
    assert _structured.verify_structure(slab, st, parts)[0]


def test_no_structure_where_there_is_none():
    wl = np.linspace(400.0, 700.0, 16)
    stack = ls.Stack(1.0, [ls.Layer(1.5, 20000.0, coherent=False, alpha=1e-5, name="v")], ls.LambertianBackground(1.5, 0.5))
    g = ls.Directional(45.0, 0.0)
    y = np.asarray(ls.reflectance(stack, wl, g))[None]
    basis_only = ft.Objective(stack, wl, ft.Dataset(g, y, sigma=SIGMA), [ft.alpha("v", basis=4), ft.thickness("v")])
    assert _fit_functions.structure_for(basis_only, "auto", "lm") is None
    with pytest.raises(LayerstackError, match="no parameter is free per wavelength"):
        _fit_functions.structure_for(basis_only, "structured", "lm")
    smooth = ft.Objective(stack, wl, ft.Dataset(g, y, sigma=SIGMA), [ft.rho_g(basis="free", smoothness=1.0)])
    with pytest.raises(LayerstackError, match="smoothness"):
        ft.fit(smooth, structure="structured")
    with pytest.raises(LayerstackError, match="structure must be one of"):
        ft.fit(smooth, structure="sparse")


# ----------------------------------------------------------------------------- structured = dense
def test_slab_n_and_alpha_free_structured_equals_dense_and_numpy(slab):
    s = ft.fit(slab, structure="structured")
    d = ft.fit(slab, structure="dense")
    assert s.converged and d.converged and s.rank == slab.n_parameters
    assert _rel(s.x, d.x) <= 1e-10
    assert _rel(s.x_stderr, d.x_stderr) <= 1e-10
    assert _cov_rel(s.covariance, d.covariance) <= 1e-10
    # NumPy re-derivation: C = (J^T J)^-1 from the full Jacobian at the solution (σ given)
    scale = slab.layout.scale
    args = slab.args()
    J = np.asarray(jax.jacfwd(lambda z: slab.residuals(z * jnp.asarray(scale), args, slab.optics))(
        jnp.asarray(s.x / scale)))
    C = np.linalg.inv(J.T @ J) * np.outer(scale, scale)
    assert _cov_rel(s.covariance, C) <= 1e-8


def test_calibration_rho_g_free_structured_equals_dense_and_scipy(calibration):
    from scipy.optimize import least_squares

    obj, _, _ = calibration
    s = ft.fit(obj, structure="structured")
    d = ft.fit(obj, structure="dense")
    assert s.converged and d.converged
    assert _rel(s.x, d.x) <= 1e-10
    assert _rel(s.x_stderr, d.x_stderr) <= 1e-10
    assert _cov_rel(s.covariance, d.covariance) <= 1e-10
    # the minimum itself, by scipy on the same residuals (its own Jacobian by finite differences)
    layout = obj.layout
    res = jax.jit(lambda z: obj.residuals(z * jnp.asarray(layout.scale), obj.args(), obj.optics))
    sol = least_squares(lambda z: np.asarray(res(z)), s.x / layout.scale * 1.001,
                        bounds=(layout.lower / layout.scale, layout.upper / layout.scale), xtol=1e-14, ftol=1e-14,
                        gtol=1e-14, x_scale=1.0)
    assert np.max(np.abs(sol.x * layout.scale - s.x) / s.x_stderr) < 1e-3


def test_batched_structured_fits_equal_single_ones(calibration):
    obj, clean, bare = calibration
    rng = np.random.default_rng(7)
    ys = [clean + SIGMA * rng.standard_normal((3,) + clean.shape), bare + SIGMA * rng.standard_normal((3,) + bare.shape)]
    b = ft.fit_batch(obj, ys, chunk_size=3, progress=False)
    assert b.converged.all()
    for k in range(3):
        one = ft.fit(obj, data=[ys[0][k], ys[1][k]])
        assert _rel(b.x[k], one.x) <= 1e-8
        assert _rel(b.stderr[k], one.x_stderr) <= 1e-8
    dense = ft.fit_batch(obj, ys, chunk_size=3, progress=False, structure="dense")
    assert _rel(dense.x, b.x) <= 1e-10 and _rel(dense.stderr, b.stderr) <= 1e-10


def test_other_methods_use_the_compressed_jacobian_for_statistics(slab):
    """L-BFGS-B solves with the gradient alone; its statistics come from the compressed Jacobian:
    the same standard errors as the dense path at the same point."""
    s = ft.fit(slab, method="lbfgsb", structure="structured", max_steps=2000)
    d = ft.fit(slab, structure="dense")
    assert s.converged
    assert np.max(np.abs(s.x - d.x) / d.x_stderr) < 1e-2
    assert _rel(s.x_stderr, d.x_stderr) < 1e-3


# ----------------------------------------------------------------------------- coverage
@pytest.mark.slow
def test_coverage_401_wavelengths_rho_g_and_alpha_free():
    """α(λ) and ρg(λ) both free at 401 wavelengths (805 parameters: two spectral blocks, three
    thicknesses), 100 noisy replicates fitted with the compiled structured solver: the fraction
    of values within ±2 standard errors of the truth is that of a Gaussian (95.4 %; 90–98 %
    accepted)."""
    obj, clean, bare, truth = _calibration(401, "free")
    assert _fit_functions.structure_for(obj, "auto", "lm").b == 2
    rng = np.random.default_rng(11)
    inside, total, converged = 0, 0, 0
    for _ in range(100):
        r = ft.fit(obj, data=[clean + SIGMA * rng.standard_normal(clean.shape),
                              bare + SIGMA * rng.standard_normal(bare.shape)])
        converged += r.converged
        z = np.abs(r.x - truth) / r.x_stderr
        inside += int(np.sum(z <= 2.0))
        total += z.size
    assert converged >= 95
    frac = inside / total
    print(f"coverage: {frac:.4f} of {total} values within ±2σ; {converged}/100 converged")
    assert 0.90 <= frac <= 0.98, frac


def test_a_fixed_value_inside_a_free_spectrum():
    """α(λ) free except at two wavelengths held at their start (absent from the blocks there):
    still the dense path's values, standard errors and covariance."""
    wl = np.linspace(420.0, 680.0, 20)
    a_true = 3e-6 * (1 + 0.5 * np.sin(np.linspace(0, 4, 20)))
    g = ls.Specular(0.0, "T")

    def stack(h, a):
        return ls.Stack(1.0, [ls.Layer(1.5, h, coherent=False, alpha=a, name="slab")], ls.Substrate(1.0))

    h = np.array([200_000.0, 350_000.0])
    rng = np.random.default_rng(5)
    y = np.stack([np.asarray(ls.reflectance(stack(x, jnp.asarray(a_true)), wl, g)) for x in h])
    y = y + SIGMA * rng.standard_normal(y.shape)
    fixed = np.zeros(20, bool)
    fixed[[3, 11]] = True
    start = np.where(fixed, a_true, 2e-6)
    params = [ft.thickness("slab", value=[200_000.0, 330_000.0], per_sample=True, fixed=np.array([True, False])),
              ft.Parameter(("layers", "slab", "alpha"), "alpha", "alpha", value=start, basis="free", fixed=fixed)]
    obj = ft.Objective(stack(h[0], jnp.asarray(start)), wl, ft.Dataset(g, y, sigma=SIGMA), params, n_samples=2)
    st = _fit_functions.structure_for(obj, "structured", "lm")
    assert not st.present[[3, 11], 0].any() and st.present.sum() == 18
    s = ft.fit(obj, structure="structured")
    d = ft.fit(obj, structure="dense")
    assert s.converged and d.converged and obj.n_parameters == 19
    assert _rel(s.x, d.x) <= 1e-10
    assert _rel(s.x_stderr, d.x_stderr) <= 1e-10
    assert _cov_rel(s.covariance, d.covariance) <= 1e-10


def test_trf_with_the_sparse_compressed_jacobian(calibration):
    """scipy's TRF (host) gets the compressed Jacobian as a sparse matrix: the same minimum as
    the structured LM fit, within a small fraction of a standard error."""
    obj, _, _ = calibration
    t = ft.fit(obj, method="trf", structure="structured")
    s = ft.fit(obj, structure="structured")
    assert t.converged
    assert np.max(np.abs(t.x - s.x) / s.x_stderr) < 1e-2
    assert _rel(t.x_stderr, s.x_stderr) < 1e-3


def test_per_sample_free_spectrum_and_a_bare_dataset():
    """ρg(λ) free per sample (one spectral block per sample; the bare background reads sample
    0's), each sample read at 45°/0° and in a sphere, α on a basis (known thicknesses): the
    structured fit is the dense one."""
    wl = np.linspace(400.0, 700.0, 18)
    geometries = (ls.Directional(45.0, 0.0), ls.Sphere(8.0))
    rho = np.stack([0.3 + 0.3 * np.linspace(0, 1, 18), 0.5 - 0.2 * np.linspace(0, 1, 18)])
    a_true = 2e-5 * (1 + 0.3 * np.cos(np.linspace(0, 3, 18)))

    def st(h, r, a=a_true):
        return ls.Stack(1.0, [ls.Layer(1.52, h, coherent=False, alpha=a, name="v")], ls.LambertianBackground(1.5, r))

    rng = np.random.default_rng(8)
    datasets = []
    for g in geometries:
        y = np.stack([np.asarray(ls.reflectance(st(h, jnp.asarray(r)), wl, g)) for h, r in zip([10_000.0, 30_000.0], rho)])
        datasets.append(ft.Dataset(g, y + SIGMA * rng.standard_normal(y.shape), sigma=SIGMA))
    g = geometries[0]
    bare = np.asarray(ls.reflectance(ls.Stack(1.0, [], ls.LambertianBackground(1.5, jnp.asarray(rho[0]))), wl, g))
    datasets.append(ft.Dataset(g, bare + SIGMA * rng.standard_normal(18), sigma=SIGMA, bare=True))
    params = [ft.thickness("v", value=[10_000.0, 30_000.0], per_sample=True, fixed=np.array([True, True])),
              ft.alpha("v", basis=3, value=[1.5e-5, 1.5e-5, 1.5e-5]),
              ft.rho_g(basis="free", per_sample=True, value=np.full((2, 18), 0.45))]
    obj = ft.Objective(st(10_000.0, 0.45, 1.5e-5), wl, datasets, params, n_samples=2)
    stc = _fit_functions.structure_for(obj, "structured", "lm")
    assert (stc.b, stc.g, stc.k) == (2, 3, 5)
    s = ft.fit(obj, structure="structured")
    d = ft.fit(obj, structure="dense")
    assert s.converged and d.converged and s.rank == obj.n_parameters
    assert _rel(s.x, d.x) <= 1e-10
    assert _rel(s.x_stderr, d.x_stderr) <= 1e-10
    assert _cov_rel(s.covariance, d.covariance) <= 1e-10
