"""Differentiability: jax.grad / jax.jacfwd against central finite differences (float64) for every
kind of parameter, NaN-free values and gradients at the numerical traps, jit / vmap, and one
compilation per model shape.

The finite differences are taken on the same library function (a derivative check cannot have
another source of values), evaluated at x ± h in float64: they test the autodiff rules
(custom JVPs, double-where guards, traced quadrature split points), not the physics.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import layerstack_jax as ls

RTOL = 1e-6
WL = jnp.array([420.0, 530.0, 610.0, 700.0])


def _fd_check(f, params, steps, *, rtol=RTOL, atol=1e-12):
    """Compare jax.grad(f)(params) (dict of scalars) with central differences of f (the values come
    from the same compiled jit(value_and_grad(f)): one compilation per check)."""
    vg = jax.jit(jax.value_and_grad(f))
    _, g = vg(params)
    report = {}
    for k, x in params.items():
        h = steps[k]
        up = dict(params, **{k: x + h})
        dn = dict(params, **{k: x - h})
        fd = (float(vg(up)[0]) - float(vg(dn)[0])) / (2 * h)
        gk = float(g[k])
        assert math.isfinite(gk), k
        report[k] = (gk, fd)
        assert abs(gk - fd) <= rtol * abs(fd) + atol, (k, gk, fd, abs(gk - fd) / max(abs(fd), 1e-300))
    return report


def _jac_fd_check(f, x, h, *, rtol=RTOL, atol=1e-12):
    """jax.jacfwd of an array -> array map against central differences column by column."""
    both = jax.jit(lambda x: (f(x), jax.jacfwd(f)(x)))
    J = np.asarray(both(x)[1])
    x = np.asarray(x)
    for i in range(x.size):
        e = np.zeros_like(x)
        e.flat[i] = h
        col = (np.asarray(both(jnp.asarray(x + e))[0]) - np.asarray(both(jnp.asarray(x - e))[0])) / (2 * h)
        assert np.all(np.isfinite(J[..., i]))
        assert np.all(np.abs(J[..., i] - col) <= rtol * np.abs(col) + atol), (i, J[..., i], col)
    return J


# ----------------------------------------------------------------------------------------------
# model A: specular response of a mixed stack
# ----------------------------------------------------------------------------------------------
def _model_a(p):
    st = ls.Stack(
        p["n0"],
        [
            ls.Layer(ls.Index(p["n1"], p["k1"]), p["d1"]),  # coherent film, Index(n, k) leaves
            ls.Layer(ls.Cauchy(p["A"], p["B"], 0.0, p["kc"]), p["d2"]),  # coherent Cauchy film
            ls.Layer(ls.Index(p["n3"], p["k3"]), p["h3"], coherent=False),  # thick, complex index
            ls.Layer(1.45, p["h4"], coherent=False, alpha=p["alpha4"]),  # thick, α given
        ],
        ls.Substrate(ls.Index(p["ns"], p["ks"])),
    )
    out = ls.specular(st, WL, angle_rad=jnp.stack([p["theta"], 0.2]))
    w = jnp.arange(1.0, 1.0 + WL.size)
    return jnp.sum(w * (out.R_front + 0.7 * out.T_front + 0.3 * out.R_back))


PARAMS_A = dict(
    n0=1.05, n1=1.9, k1=0.3, d1=85.0, A=1.48, B=0.012, kc=0.02, d2=140.0,
    n3=1.6, k3=2e-6, h3=5e3, h4=8e3, alpha4=3e-5, ns=1.7, ks=0.01, theta=0.6,
)
STEPS_A = {k: 1e-5 * max(abs(v), 1.0) for k, v in PARAMS_A.items()}
STEPS_A.update(k3=1e-9, alpha4=1e-8, ks=1e-6, B=1e-6, kc=1e-6)


def test_grad_specular_all_parameter_kinds():
    """Thickness (coherent, incoherent), α, Index n and k (film, thick layer, substrate, ambient),
    Cauchy A, B, k, and the angle of incidence."""
    p = {k: jnp.asarray(v) for k, v in PARAMS_A.items()}
    _fd_check(_model_a, p, STEPS_A)


# ----------------------------------------------------------------------------------------------
# model B: a stack over a Lambertian background (hemispherical quadrature inside)
# ----------------------------------------------------------------------------------------------
def _stack_b(p, rho, alpha):
    return ls.Stack(
        p["n0"],
        [
            ls.Layer(ls.Index(p["nf"], p["kf"]), p["df"]),
            ls.Layer(p["nv"], p["hv"], coherent=False, alpha=alpha),
        ],
        ls.LambertianBackground(p["ng"], rho),
    )


PARAMS_B = dict(n0=1.0, nf=2.1, kf=0.05, df=60.0, nv=1.52, hv=2e4, ng=1.6, inc=30.0, view=10.0, alpha=2e-5, rho=0.7)
STEPS_B = {k: 1e-5 * max(abs(v), 1.0) for k, v in PARAMS_B.items()}
STEPS_B.update(kf=1e-6, alpha=1e-9, rho=1e-6)


def test_grad_background_all_parameter_kinds():
    """Through the quadrature (its split points move with n_v, n_g): ambient, film and varnish
    indices, thicknesses, background index n_g, scalar α, scalar ρg, incidence and viewing angles
    (degrees, geometry leaves), for the sphere (SCI) and the radiance detector."""

    def f(p):
        st = _stack_b(p, p["rho"], p["alpha"])
        sphere = ls.reflectance(st, WL, ls.Sphere(p["inc"], "included"))
        radiance = ls.reflectance(st, WL, ls.Directional(p["inc2"], p["view"]))
        return jnp.sum(sphere + 0.5 * radiance)

    p = {k: jnp.asarray(v) for k, v in PARAMS_B.items()}
    p["inc2"] = jnp.asarray(50.0)
    _fd_check(f, p, dict(STEPS_B, inc2=STEPS_B["inc"]))


def test_jacobian_alpha_and_rho_spectra():
    """jacfwd with respect to α(λ) and ρg(λ) given on the wavelength grid (Jacobians wl × wl:
    diagonal, since each wavelength is independent), against finite differences."""
    p = {k: jnp.asarray(v) for k, v in PARAMS_B.items()}
    alpha0 = jnp.array([1e-5, 3e-5, 1e-6, 6e-5])
    rho0 = jnp.array([0.2, 0.5, 0.8, 0.95])
    geom = ls.Directional(45.0, 0.0)

    # small step: near grazing the Beer exponent α h / cos θ is large, so FD needs α-steps ≪ 1e-9
    J = _jac_fd_check(lambda a: ls.reflectance(_stack_b(p, rho0, a), WL, geom), alpha0, 1e-12, rtol=1e-6)
    assert np.all(np.abs(J - np.diag(np.diag(J))) == 0.0)
    assert np.all(np.diag(J) < 0)  # more absorption, darker
    J = _jac_fd_check(lambda r: ls.reflectance(_stack_b(p, r, alpha0), WL, ls.Sphere(8.0)), rho0, 1e-6)
    assert np.all(np.abs(J - np.diag(np.diag(J))) == 0.0)
    assert np.all(np.diag(J) > 0)


def test_jacobian_tabulated_rho_and_alpha_spectra():
    """ρg as a TabulatedSpectrum and α as an array, differentiated with respect to the table values
    (interpolation weights spread each table value over neighbouring grid wavelengths)."""
    p = {k: jnp.asarray(v) for k, v in PARAMS_B.items()}
    table_wl = [400.0, 550.0, 720.0]

    def f(values):
        st = _stack_b(p, ls.TabulatedSpectrum(table_wl, values), 2e-5)
        return ls.reflectance(st, WL, ls.Sphere(8.0, "included"))

    J = _jac_fd_check(f, jnp.array([0.3, 0.6, 0.9]), 1e-6)
    assert J.shape == (WL.size, 3)


# ----------------------------------------------------------------------------------------------
# NaN-free values and gradients at the traps
# ----------------------------------------------------------------------------------------------
def _all_finite(tree):
    return all(bool(jnp.all(jnp.isfinite(x))) for x in jax.tree_util.tree_leaves(tree))


TH_C = math.asin(1.0 / 1.5)


def test_no_nan_gradients_at_critical_grazing_and_90():
    """glass ambient (1.5) | film 1.0 (its own critical angle at θc) | absorbing film | thick layer
    n = 1.0, α = 0 (TIR inside) | exit 1.0 (critical), at θc exactly, 89.9° and 90° (one call,
    angle axis): values and gradients w.r.t. every leaf (per-angle for θ) finite."""
    assert 1.5 * math.sin(TH_C) == 1.0

    def f(p):
        st = ls.Stack(
            p["n0"],
            [
                ls.Layer(ls.Index(p["n1"]), p["d1"]),
                ls.Layer(ls.Index(p["n2"], p["k2"]), p["d2"]),
                ls.Layer(ls.Index(p["n3"]), p["h3"], coherent=False, alpha=p["a3"]),
            ],
            ls.Substrate(ls.Index(p["ns"])),
        )
        out = ls.specular(st, WL, angle_rad=p["theta"])
        return jnp.sum(out.R_front + out.T_front + out.R_back + out.T_back)

    theta = jnp.array([TH_C, math.radians(89.9), math.pi / 2])
    p = dict(n0=1.5, n1=1.0, d1=80.0, n2=2.0, k2=0.3, d2=40.0, n3=1.0, h3=1e4, a3=0.0, ns=1.0)
    p = {k: jnp.asarray(v) for k, v in p.items()}
    p["theta"] = theta
    v, g = jax.jit(jax.value_and_grad(f))(p)
    assert _all_finite(v) and _all_finite(g), g
    assert g["theta"].shape == (3,)


def test_no_nan_gradients_at_the_exact_critical_angle_of_a_bare_interface():
    """d/dθ at the branch point (q_exit = 0 exactly) is the documented 0, not NaN/inf; d/dn too."""

    def f(theta, n_exit):
        st = ls.Stack(1.5, [], ls.Substrate(ls.Index(n_exit)))
        return jnp.sum(ls.specular(st, WL[:1], angle_rad=theta).R_front)

    v, g = jax.jit(jax.value_and_grad(f, argnums=(0, 1)))(jnp.asarray(TH_C), jnp.asarray(1.0))
    assert _all_finite(v) and _all_finite(g)


def test_no_nan_gradients_under_a_ten_micron_metal_layer():
    """10 µm of metal over a film and a background: the phase factor underflows; values and
    gradients (metal n, k, thickness, everything below, background) stay finite; R is the bulk
    metal's, and what lies below has zero derivative."""

    def f(p):
        st = ls.Stack(
            1.0,
            [
                ls.Layer(ls.Index(p["nm"], p["km"]), p["dm"]),
                ls.Layer(ls.Index(p["nb"], 0.1), p["db"]),
                ls.Layer(1.5, 2e4, coherent=False, alpha=p["a"]),
            ],
            ls.LambertianBackground(p["ng"], p["rho"]),
        )
        return jnp.sum(ls.reflectance(st, WL, ls.Sphere(p["inc"], "included")))

    p = dict(nm=0.5, km=5.0, dm=1e4, nb=1.8, db=50.0, a=0.0, ng=1.5, rho=0.8, inc=8.0)
    p = {k: jnp.asarray(v) for k, v in p.items()}
    v, g = jax.jit(jax.value_and_grad(f))(p)
    assert _all_finite(v) and _all_finite(g), g
    for k in ("nb", "db", "a", "ng", "rho"):
        assert float(g[k]) == 0.0, k
    assert float(g["nm"]) != 0.0 and float(g["km"]) != 0.0


# ----------------------------------------------------------------------------------------------
# jit, vmap, recompilation
# ----------------------------------------------------------------------------------------------
def _fit_stack(d, h, rho):
    return ls.Stack(
        1.0,
        [ls.Layer(ls.Index(1.9, 0.05), d), ls.Layer(1.5, h, coherent=False, alpha=1e-5)],
        ls.LambertianBackground(1.5, rho),
    )


def test_vmap_over_thickness_samples_equals_loop_and_jit():
    """jit(vmap(f)) over thickness samples (a coherent film and a thick layer) equals a Python loop
    of jit(f) calls (one compile for the loop)."""
    d = jnp.linspace(20.0, 200.0, 5)
    h = jnp.linspace(5e3, 3e4, 5)
    th = jnp.linspace(0.0, 1.2, 5)

    def f(d, h, th):
        st = _fit_stack(d, h, 0.6)
        return ls.reflectance(st, WL, ls.Sphere(8.0, "included")), ls.specular(st, WL, angle_rad=th).R_front

    fj = jax.jit(f)
    batched = jax.jit(jax.vmap(f))(d, h, th)
    loop = [fj(di, hi, ti) for di, hi, ti in zip(d, h, th)]
    assert batched[0].shape == (5, WL.size) and batched[1].shape == (5, 2, WL.size)
    for i in range(5):
        assert float(jnp.max(jnp.abs(batched[0][i] - loop[i][0]))) <= 1e-14
        assert float(jnp.max(jnp.abs(batched[1][i] - loop[i][1]))) <= 1e-14
    assert fj._cache_size() == 1


def test_one_compilation_per_model_shape():
    """Changing only values (thicknesses, indices, α, ρg, angles) never retraces."""

    @eqx.filter_jit
    @eqx.debug.assert_max_traces(max_traces=1)
    def model(stack, geometry):
        return ls.reflectance(stack, WL, geometry)

    rng = np.random.default_rng(0)
    for _ in range(4):
        st = ls.Stack(
            jnp.asarray(1.0),
            [
                ls.Layer(ls.Index(jnp.asarray(rng.uniform(1.3, 2.3)), jnp.asarray(rng.uniform(0, 0.2))), jnp.asarray(rng.uniform(10, 200))),
                ls.Layer(ls.Index(jnp.asarray(rng.uniform(1.3, 1.7))), jnp.asarray(rng.uniform(1e3, 3e4)), coherent=False, alpha=jnp.asarray(rng.uniform(0, 1e-4, WL.size))),
            ],
            ls.LambertianBackground(ls.Index(jnp.asarray(rng.uniform(1.3, 1.7))), jnp.asarray(rng.uniform(0, 1, WL.size))),
        )
        geom = ls.Directional(jnp.asarray(rng.uniform(0, 80)), jnp.asarray(rng.uniform(0, 80)))
        out = model(st, geom)
        assert out.shape == (WL.size,) and _all_finite(out)

    # plain jax.jit with Python-float leaves: they are traced too
    f = jax.jit(lambda d, n: ls.specular(ls.Stack(1.0, [ls.Layer(n, d)], ls.Substrate(1.5)), WL, angle_rad=0.3).R_front)
    for d, n in ((10.0, 1.4), (120.0, 2.2), (300.0, 1.7)):
        f(d, n)
    assert f._cache_size() == 1


def test_grad_inside_jit_of_a_fit_objective():
    """A least-squares objective over (thickness, α, ρg) compiles once and its gradient matches FD."""
    target = jnp.array([0.30, 0.35, 0.42, 0.40])

    def loss(p):
        st = ls.Stack(
            1.0,
            [ls.Layer(ls.Index(1.9, 0.05), p["d"]), ls.Layer(1.5, 2e4, coherent=False, alpha=p["alpha"])],
            ls.LambertianBackground(1.5, p["rho"]),
        )
        return jnp.sum((ls.reflectance(st, WL, ls.Sphere(8.0, "included")) - target) ** 2)

    p = dict(d=jnp.asarray(90.0), alpha=jnp.asarray(2e-5), rho=jnp.asarray(0.6))
    _fd_check(loss, p, dict(d=1e-3, alpha=1e-9, rho=1e-6))


# ----------------------------------------------------------------------------------------------
# closed-form derivative of the hemispherical adding sums (layerstack_jax._kernels.adding_sums)
# ----------------------------------------------------------------------------------------------
def _mixed_over_background(h, alpha, n_mid):
    layers = [
        ls.Layer(1.5, h[0], coherent=False, alpha=alpha),
        ls.Layer(ls.Index(2.0, 0.02), 70.0),  # absorbing coherent film between thick layers
        ls.Layer(ls.Index(n_mid), h[1], coherent=False, alpha=2e-5),
        ls.Layer(1.45, h[2], coherent=False, alpha=0.5 * alpha),
    ]
    return ls.Stack(1.0, layers, ls.LambertianBackground(1.52, 0.6))


def test_closed_form_adding_derivative_equals_generic_autodiff():
    """Thicknesses and α(λ) reach the diffuse sums only through Beer factors, whose derivative is
    written in closed form (one extra sweep). With an index also differentiated the generic
    autodiff path is taken: both paths, forward and reverse mode, agree to 1e-11 relative, for
    the sphere (back-side sums) and the front-side diffuse r and t. (The generic path is checked
    against central differences in test_grad_background_all_parameter_kinds.)"""
    h0 = jnp.array([2e4, 8e3, 1.5e4])
    a0 = jnp.array([1e-5, 3e-5, 2e-6, 6e-5])

    def fn(h, a, n):
        st = _mixed_over_background(h, a, n)
        front = ls.diffuse(ls.Stack(st.ambient, st.layers, ls.Substrate(1.52)), WL, "front")
        return jnp.concatenate([ls.reflectance(st, WL, ls.Sphere(8.0)), front.r, front.t])

    generic = jax.jit(jax.jacfwd(fn, argnums=(0, 1, 2)))(h0, a0, jnp.asarray(1.6))
    for mode in (jax.jacfwd, jax.jacrev):
        fast = jax.jit(mode(lambda h, a: fn(h, a, 1.6), argnums=(0, 1)))(h0, a0)
        for k in range(2):
            scale = float(jnp.max(jnp.abs(generic[k])))
            assert scale > 0
            err = float(jnp.max(jnp.abs(fast[k] - generic[k])))
            assert err <= 1e-11 * scale, (mode.__name__, k, err / scale)


def _random_sums_case(rng, n_layers, node=7, wl=5):
    """Physical random inputs for layerstack_jax._kernels.adding_sums.hemispherical_sums: packets with
    R + T <= 1 on each side, slant paths with some nodes past the layer's critical angle."""
    from layerstack_jax._kernels.coherent import PacketIntensities

    def packet():
        R_f, R_b = rng.uniform(0.0, 0.9, (2, 2, node, 1))
        T = rng.uniform(0.0, 1.0, (2, node, 1)) * (1.0 - np.maximum(R_f, R_b))
        return PacketIntensities(jnp.asarray(R_f), jnp.asarray(T), jnp.asarray(R_b), jnp.asarray(T * 0.9))

    packets = tuple(packet() for _ in range(n_layers + 1))
    cos = rng.uniform(-0.2, 1.0, (n_layers, node, 1))  # some nodes not reached (cos <= 0)
    im_q = rng.uniform(0.0, 1e-4, (n_layers, node, 1))
    paths = tuple((jnp.asarray(c), jnp.asarray(q)) for c, q in zip(cos, im_q))
    w = jnp.asarray(rng.uniform(0.0, 0.3, (node, 1)))
    wavelength = jnp.linspace(400.0, 700.0, wl)
    return packets, paths, w, wavelength


def test_adding_sums_closed_form_equals_generic_jvp_for_every_input_shape():
    """The closed-form derivative of hemispherical_sums (adjoint sweep) against the generic
    automatic derivative of the same sweep (`_plain`), for thicknesses that are scalars, spectra
    (wl,) or vary per node (node, wl); α None, scalar or a spectrum; light from either side; with
    and without transmittance; 1 to 4 thick layers. Forward and reverse mode, to 1e-12 relative."""
    from layerstack_jax._kernels import adding_sums as S

    rng = np.random.default_rng(7)
    node, wl = 7, 5
    shapes = [(), (wl,), (node, wl)]
    for case in range(8):
        L = 1 + case % 4
        packets, paths, w, wavelength = _random_sums_case(rng, L, node, wl)
        thickness = tuple(jnp.asarray(rng.uniform(1e3, 3e4, shapes[(case + j) % 3])) for j in range(L))
        alpha = tuple(None if (case + j) % 3 == 0 else jnp.asarray(rng.uniform(1e-6, 5e-5, shapes[(case + 2 * j) % 2]))
                      for j in range(L))
        back, transmits = bool(case % 2), case % 3 != 1
        args = (packets, paths)

        def fast(h, a):
            return jnp.concatenate(S.hemispherical_sums(*args, h, a, wavelength, w, back, transmits))

        def generic(h, a):
            return jnp.concatenate(S._plain(*args, h, a, wavelength, w, back, transmits))

        np.testing.assert_allclose(fast(thickness, alpha), generic(thickness, alpha), rtol=1e-14, atol=1e-16)
        derivatives = jax.jit(lambda h, a: [mode(f, argnums=(0, 1))(h, a) for mode, f in
                                            ((jax.jacfwd, fast), (jax.jacrev, fast), (jax.jacfwd, generic))])
        forward, reverse, want = derivatives(thickness, alpha)
        for got, mode in ((forward, "forward"), (reverse, "reverse")):
            for g, e in zip(jax.tree_util.tree_leaves(got), jax.tree_util.tree_leaves(want), strict=True):
                scale = max(float(jnp.max(jnp.abs(e))), 1e-300)
                assert float(jnp.max(jnp.abs(g - e))) <= 1e-12 * scale, (case, mode)


def test_adding_sums_derivative_against_finite_differences():
    """One random 3-layer case, both sides: d(r, t)/dh and d(r, t)/dα of the closed form against
    central differences of the primal (1e-6 relative to each column's largest entry)."""
    from layerstack_jax._kernels import adding_sums as S

    rng = np.random.default_rng(11)
    packets, paths, w, wavelength = _random_sums_case(rng, 3)
    h0 = jnp.array([2e4, 5e3, 1.2e4])
    a0 = jnp.array([6e-5, 1e-4, 3e-5])  # κh ~ 1: the derivatives are well above round-off
    for back in (True, False):
        def f(h, a):
            return jnp.concatenate(S.hemispherical_sums(packets, paths, tuple(h), tuple(a), wavelength, w, back, True))

        f = jax.jit(f)
        Jh, Ja = jax.jit(jax.jacfwd(f, argnums=(0, 1)))(h0, a0)
        for J, step, arg in ((Jh, 1.0, 0), (Ja, 2e-8, 1)):
            for i in range(3):
                e = jnp.zeros(3).at[i].set(step)
                up = f(h0 + e, a0) if arg == 0 else f(h0, a0 + e)
                dn = f(h0 - e, a0) if arg == 0 else f(h0, a0 - e)
                fd = (up - dn) / (2 * step)
                assert float(jnp.max(jnp.abs(fd))) > 0
                np.testing.assert_allclose(J[:, i], fd, rtol=1e-6, atol=1e-6 * float(jnp.max(jnp.abs(fd))))
