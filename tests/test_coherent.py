"""Coherent thin-film stacks (Rouard / Airy recursion) against tmm.coh_tmm and closed forms.

Every expected value comes from ``tmm`` (via tests/reference.py) or from a closed form written
here; nothing is computed with layerstack_jax except the quantity under test.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import layerstack_jax as ls
import reference as ref
from _helpers import INF, build_stack, max_abs, pad_index_matched, snell_angle, specular_jit, tree_stack

TOL = 1e-12

# ----------------------------------------------------------------------------------------------
# random asymmetric stacks
# ----------------------------------------------------------------------------------------------
N_PER_K = 17  # 12 layer counts x 17 = 204 stacks
N_ANG = 6
N_WL = 3


def _random_index(rng):
    u = rng.random()
    if u < 0.35:  # dielectric, including low-index films (evanescent at high angles)
        return complex(rng.uniform(1.0, 3.5), 0.0)
    if u < 0.55:  # weakly absorbing (semiconductor-like)
        return complex(rng.uniform(1.3, 4.5), rng.uniform(0.0, 0.6))
    return complex(rng.uniform(0.05, 3.0), rng.uniform(0.5, 5.0))  # metal, k up to 5


def _random_coherent_stack(rng, K):
    n0 = float(rng.uniform(1.0, 2.0))
    n = [complex(n0)] + [_random_index(rng) for _ in range(K)]
    n.append(complex(rng.uniform(1.0, 4.0), 0.0) if rng.random() < 0.7 else _random_index(rng))
    d = [INF] + [float(rng.uniform(0.5, 300.0)) for _ in range(K)] + [INF]
    angles = np.concatenate([[0.0, 89.0], rng.uniform(0.0, 89.0, N_ANG - 2)])
    wl = rng.uniform(300.0, 1200.0, N_WL)
    return n, d, np.deg2rad(angles), wl


def _groups(K_list, seed):
    """Random stacks grouped by padded shape: K <= 4 -> 4 layers, 5..8 -> 8 (unrolled recursion),
    9..12 -> 12 (lax.scan recursion). The largest K of each group is not padded at all."""
    rng = np.random.default_rng(seed)
    groups = {}
    for K in K_list:
        target = 4 if K <= 4 else (8 if K <= 8 else 12)
        for _ in range(N_PER_K):
            n, d, ang, wl = _random_coherent_stack(rng, K)
            n_pad, d_pad, _, _ = pad_index_matched(n, d, target, rng)
            groups.setdefault(target, []).append((n, d, ang, wl, n_pad, d_pad))
    return groups


def _tmm_reference(n, d, ang, wl):
    """(R_f, T_f, R_b, T_b) shaped (ang, 2, wl); back side NaN where it does not exist."""
    shape = (len(ang), 2, len(wl))
    Rf, Tf = np.empty(shape), np.empty(shape)
    Rb, Tb = np.full(shape, np.nan), np.full(shape, np.nan)
    n = np.asarray(n, dtype=complex)
    d = np.asarray(d, dtype=float)
    n0, ne = n[0].real, n[-1]
    clamped = np.zeros(shape, bool)
    for ia, th in enumerate(ang):
        s = n0 * math.sin(th)
        back = ne.imag == 0.0 and s < ne.real * (1 - 1e-9)
        th_b = snell_angle(n0, ne.real, th) if back else None
        for iw, lam in enumerate(wl):
            clamped[ia, :, iw] = ref.tmm_is_clamped(n, d, None, th, lam)
            for ip, pol in enumerate("sp"):
                Rf[ia, ip, iw], Tf[ia, ip, iw] = ref.coh_stack_R_T(pol, n, d, th, lam)
                if back:
                    Rb[ia, ip, iw], Tb[ia, ip, iw] = ref.coh_stack_R_T(pol, n[::-1], d[::-1], th_b, lam)
    return Rf, Tf, Rb, Tb, clamped


@jax.jit
def _batched_specular(stacks, wl, ang):
    return jax.vmap(lambda st, w, a: ls.specular(st, w, angle_rad=a))(stacks, wl, ang)


def _run_group(items):
    stacks = tree_stack([build_stack(n_pad, d_pad, leaves=True) for (_, _, _, _, n_pad, d_pad) in items])
    wl = jnp.asarray(np.stack([it[3] for it in items]))
    ang = jnp.asarray(np.stack([it[2] for it in items]))
    return jax.tree.map(np.asarray, _batched_specular(stacks, wl, ang))


def _check_groups(groups):
    n_stacks = 0
    err = {"R_front": 0.0, "T_front": 0.0, "R_back": 0.0, "T_back": 0.0, "recip": 0.0}
    n_back = 0
    for target, items in groups.items():
        out = _run_group(items)
        assert out.R_front.shape == (len(items), N_ANG, 2, N_WL)
        for i, (n, d, ang, wl, _, _) in enumerate(items):
            Rf, Tf, Rb, Tb, clamped = _tmm_reference(n, d, ang, wl)
            ok = ~clamped
            got = {k: getattr(out, k)[i] for k in ("R_front", "T_front", "R_back", "T_back")}
            for k in got:
                assert np.all(np.isfinite(got[k])), (k, n, d)
            err["R_front"] = max(err["R_front"], max_abs(got["R_front"][ok], Rf[ok]))
            err["T_front"] = max(err["T_front"], max_abs(got["T_front"][ok], Tf[ok]))
            has_back = np.isfinite(Rb) & ok
            n_back += int(has_back.sum())
            if has_back.any():
                err["R_back"] = max(err["R_back"], max_abs(got["R_back"][has_back], Rb[has_back]))
                err["T_back"] = max(err["T_back"], max_abs(got["T_back"][has_back], Tb[has_back]))
                # reciprocity (Simonot eq. 44) for real outer media
                err["recip"] = max(err["recip"], max_abs(got["T_back"][has_back], got["T_front"][has_back]))
            n_stacks += 1
            assert max(err.values()) <= TOL, (err, n, d, ang, wl)
    return n_stacks, n_back, err


def test_random_asymmetric_stacks_against_tmm():
    """>= 200 random stacks, 1..12 layers (metals k <= 5), angles 0..89 deg, s and p, front and
    back, three wavelengths each: R, T within 1e-12 of tmm.coh_tmm."""
    groups = _groups(range(1, 13), seed=20240611)
    n_stacks, n_back, err = _check_groups(groups)
    assert n_stacks >= 200
    assert n_back > 1000  # the back side was really exercised
    print(f"\ncoherent random: {n_stacks} stacks, max errors {err}")


@pytest.mark.slow
@pytest.mark.parametrize("K", range(1, 13))
def test_random_stacks_native_shape_every_K(K):
    """Same comparison without index-matched padding: every layer count compiles its own shape."""
    rng = np.random.default_rng(1000 + K)
    items = []
    for _ in range(N_PER_K):
        n, d, ang, wl = _random_coherent_stack(rng, K)
        items.append((n, d, ang, wl, n, d))
    n_stacks, _, err = _check_groups({K: items})
    assert n_stacks == N_PER_K


def test_zero_thickness_index_matched_padding_is_a_no_op():
    """The padding used above is itself checked against the unpadded stack in eager mode."""
    rng = np.random.default_rng(7)
    n, d, ang, wl = _random_coherent_stack(rng, 3)
    n_pad, d_pad, _, _ = pad_index_matched(n, d, 5, rng)
    a = ls.specular(build_stack(n, d), wl, angle_rad=ang)
    b = ls.specular(build_stack(n_pad, d_pad), wl, angle_rad=ang)
    for x, y in zip(a, b):
        assert max_abs(x, y) <= 1e-14


# ----------------------------------------------------------------------------------------------
# closed forms
# ----------------------------------------------------------------------------------------------
def test_quarter_wave_high_reflector_closed_form():
    r"""(HL)^N H on a substrate at the design wavelength, normal incidence:
    Y = n_H^{2N+2} / (n_L^{2N} n_s), R = ((n0 - Y)/(n0 + Y))^2; s == p; R + T = 1."""
    n0, nH, nL, ns, lam0 = 1.0, 2.35, 1.38, 1.52, 550.0
    for N in (1, 3, 5):  # 3, 7 (unrolled) and 11 (scan) layers
        idx = [nH, nL] * N + [nH]
        st = build_stack([n0] + idx + [ns], [INF] + [lam0 / (4 * x) for x in idx] + [INF])
        out = specular_jit(st, jnp.array([lam0]), 0.0)
        Y = nH ** (2 * N + 2) / (nL ** (2 * N) * ns)
        R_exact = ((n0 - Y) / (n0 + Y)) ** 2
        assert out.R_front.shape == (2, 1)
        assert max_abs(out.R_front, R_exact) <= TOL
        assert max_abs(out.T_front, 1 - R_exact) <= TOL
        assert max_abs(out.R_front[0], out.R_front[1]) <= 1e-14
        # from the substrate side the same T (reciprocity), R = R_front (lossless)
        assert max_abs(out.T_back, 1 - R_exact) <= TOL
        assert max_abs(out.R_back, R_exact) <= TOL


def test_single_layer_quarter_wave_antireflection():
    """R_min = ((n0 ns - n1^2)/(n0 ns + n1^2))^2 at λ0; the same film is half-wave (absent) at
    λ0/2: R = ((n0 - ns)/(n0 + ns))^2; with n1 = sqrt(n0 ns) R = 0."""
    n0, ns, lam0 = 1.0, 1.52, 600.0
    for n1 in (1.38, math.sqrt(n0 * ns), 2.1):
        st = build_stack([n0, n1, ns], [INF, lam0 / (4 * n1), INF])
        out = specular_jit(st, jnp.array([lam0, lam0 / 2]), jnp.array([0.0]))
        R = np.asarray(out.R_front)[0]  # (2, wl)
        assert max_abs(R[:, 0], ((n0 * ns - n1**2) / (n0 * ns + n1**2)) ** 2) <= TOL
        assert max_abs(R[:, 1], ((n0 - ns) / (n0 + ns)) ** 2) <= TOL
        assert max_abs(np.asarray(out.R_front + out.T_front), 1.0) <= TOL


def test_bare_interface_fresnel_and_tir():
    """No layer at all: Fresnel per polarization from both sides, exact TIR beyond θc."""
    ang = np.deg2rad([0.0, 10.0, 30.0, 41.0, 42.0, 50.0, 70.0, 89.9])
    for n0, n1 in ((1.0, 1.5), (1.5, 1.0), (1.33, 2.4)):
        out = ls.specular(build_stack([n0, n1], [INF, INF]), jnp.array([500.0]), angle_rad=ang)
        Rs, Rp, _ = ref.fresnel_natural_R(n0, n1, ang)
        assert max_abs(out.R_front[:, 0, 0], Rs) <= TOL
        assert max_abs(out.R_front[:, 1, 0], Rp) <= TOL
        assert max_abs(out.T_front[:, 0, 0], 1 - Rs) <= TOL
        assert max_abs(out.T_front[:, 1, 0], 1 - Rp) <= TOL
        tir = n0 * np.sin(ang) >= n1
        # |r| = 1 to rounding (|q_i - i b| / |q_i + i b|), and exactly no transmitted power
        assert max_abs(np.asarray(out.R_front)[tir], 1.0) <= 1e-15
        assert np.all(np.asarray(out.T_front)[tir] == 0.0)


def test_exact_critical_angle_grazing_and_90_degrees():
    """Ambient n = 1.5 (real), exit 1.0: at θc = asin(1/1.5) the Snell invariant is exactly 1.0
    (q_exit = 0, the sqrt branch point): R = 1, T = 0, no NaN; 1e-12 rad below θc the values
    follow tmm (R has infinite slope there: 1e-9 tolerance); 89.9° against tmm; 90°: R = 1."""
    th_c = math.asin(1.0 / 1.5)
    assert 1.5 * math.sin(th_c) == 1.0  # precondition: the invariant is exactly critical
    st = build_stack([1.5, 1.0], [INF, INF])
    out = specular_jit(st, jnp.array([500.0]), jnp.array([th_c, th_c - 1e-12, math.radians(89.9), math.pi / 2]))
    for x in out:
        assert np.all(np.isfinite(np.asarray(x)))
    R, T = np.asarray(out.R_front)[..., 0], np.asarray(out.T_front)[..., 0]
    assert np.all(R[0] == 1.0) and np.all(T[0] == 0.0)
    for ip, pol in enumerate("sp"):
        Rr, Tr = ref.coh_stack_R_T(pol, [1.5, 1.0], [INF, INF], th_c - 1e-12, 500.0)
        assert abs(R[1, ip] - Rr) <= 1e-9 and abs(T[1, ip] - Tr) <= 1e-9
        assert abs(R[1, ip] + T[1, ip] - 1) <= TOL
    assert max_abs(R[2:], 1.0) <= 1e-15 and np.all(T[2:] == 0.0)

    # a coherent stack at the exact critical angle of its exit medium (films not critical)
    n = [1.5, 1.2, 2.0 + 0.3j, 1.0]
    d = [INF, 80.0, 40.0, INF]
    ang = np.array([th_c, math.radians(89.9)])
    out = specular_jit(build_stack(n, d), jnp.array([450.0, 633.0]), jnp.asarray(ang))
    for x in out:
        assert np.all(np.isfinite(np.asarray(x)))
    for iw, lam in enumerate((450.0, 633.0)):
        for ip, pol in enumerate("sp"):
            for ia, th in enumerate(ang):
                Rr, Tr = ref.coh_stack_R_T(pol, n, d, th, lam)
                assert abs(float(out.R_front[ia, ip, iw]) - Rr) <= TOL
                assert abs(float(out.T_front[ia, ip, iw]) - Tr) <= TOL
    assert np.all(np.asarray(out.T_front) == 0.0)  # exit evanescent: no power enters it


def _abeles_R_T(pol, n, d, s, lam):
    """Independent reference: Abelès characteristic matrices (numpy), valid also where a film has
    q_j = n_j cos θ_j = 0 exactly (its matrix is then the limit [[1, -i k0 d / η'], [-i η'' k0 d, 1]]
    with finite entries). Real outer media; returns (R, T) for the Snell invariant s."""
    k0 = 2 * np.pi / lam
    q = []
    for x in n:
        v = np.sqrt(complex(x) ** 2 - s * s + 0j)
        q.append(-v if v.imag < 0 else v)
    M = np.eye(2, dtype=complex)
    for j in range(1, len(n) - 1):
        nj, qj, delta = complex(n[j]), q[j], k0 * q[j] * d[j]
        sin_over_q = k0 * d[j] if qj == 0 else np.sin(delta) / qj  # sin(k0 q d)/q -> k0 d
        if pol == "s":  # η = q
            A = [[np.cos(delta), -1j * sin_over_q], [-1j * qj * np.sin(delta), np.cos(delta)]]
        else:  # η = n^2 / q
            A = [[np.cos(delta), -1j * qj * np.sin(delta) / nj**2], [-1j * nj**2 * sin_over_q, np.cos(delta)]]
        M = M @ np.array(A)
    eta = (lambda j: q[j]) if pol == "s" else (lambda j: complex(n[j]) ** 2 / q[j])
    e0, es = eta(0), eta(len(n) - 1)
    B, C = M @ np.array([1.0, es])
    r = (e0 * B - C) / (e0 * B + C)
    R = abs(r) ** 2
    T = 4 * e0.real * es.real / abs(e0 * B + C) ** 2
    return float(R), float(T)


def test_abeles_reference_agrees_with_tmm():
    """The reference used below is itself checked against tmm away from the critical angle."""
    n, d = [1.5, 1.0, 2.0 + 0.3j, 1.2, 1.5], [INF, 80.0, 40.0, 120.0, INF]
    for th in (0.0, 0.4, 0.9, 1.2):
        for pol in "sp":
            Ra, Ta = _abeles_R_T(pol, n, d, 1.5 * math.sin(th), 450.0)
            Rt, Tt = ref.coh_stack_R_T(pol, n, d, th, 450.0)
            assert abs(Ra - Rt) <= 1e-12 and abs(Ta - Tt) <= 1e-12


def test_exact_critical_angle_of_a_film():
    """glass | 100 nm air gap | glass at θc = asin(1/1.5) exactly (frustrated TIR): the response is
    continuous there; the Abelès matrix of a q = 0 film gives the limit (R_s 0.3304, R_p 0.0888).
    Same for an absorbing film below the critical one."""
    th_c = math.asin(1.0 / 1.5)
    for n, d in (([1.5, 1.0, 1.5], [INF, 100.0, INF]), ([1.5, 1.0, 2.0 + 0.3j, 1.2], [INF, 80.0, 40.0, INF])):
        out = ls.specular(build_stack(n, d), jnp.array([450.0]), angle_rad=jnp.array([th_c]))
        for ip, pol in enumerate("sp"):
            Ra, Ta = _abeles_R_T(pol, n, d, 1.0, 450.0)
            assert abs(float(out.R_front[0, ip, 0]) - Ra) <= 1e-9, (n, pol, float(out.R_front[0, ip, 0]), Ra)
            assert abs(float(out.T_front[0, ip, 0]) - Ta) <= 1e-9


@pytest.mark.parametrize("nk", [0.5 + 5.0j, 1.2 + 2.0j, 3.0 + 0.5j])
def test_ten_micron_metal_layer_is_bulk_metal(nk):
    """A 10 µm absorbing film: no overflow/NaN, R_front = Fresnel R of the bulk metal (complex
    closed form), T = 0, R_back = Fresnel R substrate->metal."""
    n0, ns = 1.0, 1.5
    ang = np.deg2rad([0.0, 30.0, 60.0, 85.0, 89.9])
    wl = np.array([400.0, 550.0, 700.0])
    out = ls.specular(build_stack([n0, nk, ns], [INF, 10_000.0, INF]), jnp.asarray(wl), angle_rad=jnp.asarray(ang))
    for x in out:
        assert np.all(np.isfinite(np.asarray(x)))

    def fresnel(n_i, n_f, th):
        s = n_i * np.sin(th)
        qi = np.sqrt(complex(n_i) ** 2 - s**2 + 0j)
        qf = np.sqrt(complex(n_f) ** 2 - s**2 + 0j)
        qf = np.where(qf.imag < 0, -qf, qf)
        rs = (qi - qf) / (qi + qf)
        rp = (n_f**2 * qi - n_i**2 * qf) / (n_f**2 * qi + n_i**2 * qf)
        return np.abs(rs) ** 2, np.abs(rp) ** 2

    Rs, Rp = fresnel(n0, nk, ang)
    assert max_abs(out.R_front[:, 0, :], Rs[:, None] * np.ones(3)) <= TOL
    assert max_abs(out.R_front[:, 1, :], Rp[:, None] * np.ones(3)) <= TOL
    assert np.all(np.asarray(out.T_front) < 1e-30)  # exp(-4πk d/λ) with k d >= 5 µm
    th_s = np.arcsin(n0 * np.sin(ang) / ns)
    Rs, Rp = fresnel(ns, nk, th_s)
    assert max_abs(out.R_back[:, 0, :], Rs[:, None] * np.ones(3)) <= TOL
    assert max_abs(out.R_back[:, 1, :], Rp[:, None] * np.ones(3)) <= TOL
    # and against tmm with the metal as a semi-infinite exit medium
    for ia, th in enumerate(ang):
        for ip, pol in enumerate("sp"):
            Rr, _ = ref.coh_stack_R_T(pol, [n0, nk], [INF, INF], th, 550.0)
            assert abs(float(out.R_front[ia, ip, 1]) - Rr) <= TOL


def test_lossless_energy_conservation_and_normal_incidence_s_equals_p():
    rng = np.random.default_rng(3)
    for K in (1, 4, 9):
        n = [1.0] + list(rng.uniform(1.2, 2.6, K)) + [1.52]
        d = [INF] + list(rng.uniform(5.0, 400.0, K)) + [INF]
        wl = jnp.linspace(380.0, 780.0, 9)
        ang = np.deg2rad([0.0, 20.0, 45.0, 70.0, 89.0])
        out = specular_jit(build_stack(n, d), wl, jnp.asarray(ang))
        assert max_abs(np.asarray(out.R_front + out.T_front), 1.0) <= TOL
        assert max_abs(np.asarray(out.R_back + out.T_back), 1.0) <= TOL
        assert max_abs(out.T_front, out.T_back) <= TOL
        assert max_abs(out.R_front[0, 0], out.R_front[0, 1]) <= 1e-14
        assert max_abs(out.T_front[0, 0], out.T_front[0, 1]) <= 1e-14
        # absorbing version: s == p at normal incidence still, and 0 <= A
        n_abs = [1.0] + [complex(x, 0.3) for x in n[1:-1]] + [1.52]
        out = specular_jit(build_stack(n_abs, d), wl, jnp.asarray(ang))
        assert max_abs(out.R_front[0, 0], out.R_front[0, 1]) <= 1e-14
        assert np.all(np.asarray(out.R_front + out.T_front) <= 1.0 + 1e-15)


def test_output_shapes_and_scalar_angle():
    st = build_stack([1.0, 1.4 + 0.1j, 1.5], [INF, 100.0, INF])
    wl = jnp.linspace(400.0, 700.0, 4)
    assert ls.specular(st, wl, angle_rad=0.3).R_front.shape == (2, 4)
    assert ls.specular(st, wl, angle_rad=jnp.zeros((3, 5))).T_back.shape == (3, 5, 2, 4)
    out = ls.specular(st, wl, angle_rad=0.3, both_sides=False)
    assert out.R_back is None and out.T_back is None
    nat = ls.specular(st, wl, angle_rad=jnp.array([0.3])).natural()
    assert nat.R_front.shape == (1, 4)
    Rr, Tr = ref.coh_stack_R_T("u", [1.0, 1.4 + 0.1j, 1.5], [INF, 100.0, INF], 0.3, 400.0)
    assert abs(float(nat.R_front[0, 0]) - Rr) <= TOL and abs(float(nat.T_front[0, 0]) - Tr) <= TOL


def test_dispersion_models_feed_the_engine():
    """Cauchy, Sellmeier (BK7: n_d = 1.5168 at 587.6 nm) and Tabulated (linear interpolation)
    films and substrates give the same response as Index with the index computed here in numpy."""
    wl = np.array([420.0, 587.6, 700.0])
    lam_um2 = (wl * 1e-3) ** 2
    B = np.array([1.03961212, 0.231792344, 1.01046945])
    C = np.array([0.00600069867, 0.0200179144, 103.560653])
    n_bk7 = np.sqrt(1 + np.sum(B[:, None] * lam_um2 / (lam_um2 - C[:, None]), axis=0))
    assert abs(n_bk7[1] - 1.5168) < 1e-4
    n_cauchy = 1.46 + 0.0045 / lam_um2 + 1e-4 / lam_um2**2
    table_wl, table_n, table_k = [400.0, 500.0, 800.0], [2.3, 2.1, 2.0], [0.5, 0.2, 0.0]
    n_tab = np.interp(wl, table_wl, table_n) + 1j * np.interp(wl, table_wl, table_k)
    models = ls.Stack(
        1.0,
        [
            ls.Layer(ls.Cauchy(1.46, 0.0045, 1e-4, 0.01), 120.0),
            ls.Layer(ls.Tabulated(table_wl, table_n, table_k), 60.0),
        ],
        ls.Substrate(ls.Sellmeier(list(B), list(C))),
    )
    out = ls.specular(models, jnp.asarray(wl), angle_rad=jnp.array([0.0, 0.7]))
    for iw, lam in enumerate(wl):
        n = [1.0, n_cauchy[iw] + 0.01j, n_tab[iw], n_bk7[iw]]
        d = [INF, 120.0, 60.0, INF]
        for ia, th in enumerate((0.0, 0.7)):
            for ip, pol in enumerate("sp"):
                R, T = ref.coh_stack_R_T(pol, n, d, th, lam)
                assert abs(float(out.R_front[ia, ip, iw]) - R) <= TOL
                assert abs(float(out.T_front[ia, ip, iw]) - T) <= TOL
