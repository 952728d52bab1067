"""Thick incoherent layers and mixed stacks (coherent films between incoherent layers).

References: ``tmm.inc_tmm`` through ``reference.inc_stack_R_T`` (complex index n + ik given to
both; TIR handled by splitting; cases where tmm's opacity clamps act are skipped with
``reference.tmm_is_clamped``), and the tmm-free Beer recursion ``reference.beer_stack_R_T`` for
layers given an absorption coefficient α.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import layerstack_jax as ls
import reference as ref
from _helpers import INF, build_stack, max_abs, pad_index_matched, snell_angle, tree_stack

TOL_TMM = 1e-9
TOL_BEER = 1e-12

#: default run: 6 coherence patterns (each one compile): adjacent thick layers (empty packets),
#: films on either side of a thick layer, a two-film packet between thick layers, alternation.
PATTERNS = ["i", "iii", "cic", "icci", "ccic", "cicic"]
#: the slow run adds the remaining patterns
PATTERNS_ALL = PATTERNS + ["ii", "ci", "ic", "icic"]
N_PER_PATTERN = 20
N_ANG, N_WL = 6, 3


def _film_index(rng):
    u = rng.random()
    if u < 0.4:
        return complex(rng.uniform(0.05, 3.0), rng.uniform(0.5, 5.0))  # metal
    if u < 0.7:
        return complex(rng.uniform(1.0, 3.0), rng.uniform(0.0, 0.3))
    return complex(rng.uniform(1.0, 3.0), 0.0)


def _random_mixed(rng, pattern, *, complex_exit=True):
    n = [complex(rng.uniform(1.0, 1.7))]
    d = [INF]
    c = ["i"]
    for ch in pattern:
        if ch == "c":
            n.append(_film_index(rng))
            d.append(float(rng.uniform(1.0, 300.0)))
        else:
            k = 0.0 if rng.random() < 0.3 else float(rng.uniform(0.0, 2e-4))
            n.append(complex(rng.uniform(1.0, 2.5), k))
            d.append(float(rng.uniform(1e3, 5e4)))
        c.append(ch)
    if complex_exit and rng.random() < 0.2:
        n.append(complex(rng.uniform(0.5, 3.0), rng.uniform(0.0, 3.0)))
    else:
        n.append(complex(rng.uniform(1.0, 2.0)))
    d.append(INF)
    c.append("i")
    ang = np.deg2rad(np.concatenate([[0.0, 89.0], rng.uniform(0.0, 89.0, N_ANG - 2)]))
    wl = rng.uniform(400.0, 1000.0, N_WL)
    return n, d, c, ang, wl


@jax.jit
def _batched(stacks, wl, ang):
    return jax.vmap(lambda st, w, a: ls.specular(st, w, angle_rad=a))(stacks, wl, ang)


def _run(items):
    stacks = tree_stack([build_stack(n, d, [x == "c" for x in c[1:-1]], leaves=True) for n, d, c, _, _ in items])
    wl = jnp.asarray(np.stack([it[4] for it in items]))
    ang = jnp.asarray(np.stack([it[3] for it in items]))
    return jax.tree.map(np.asarray, _batched(stacks, wl, ang))


def test_mixed_and_incoherent_stacks_against_tmm_inc_tmm():
    """120 random stacks of 6 coherence patterns (thick layers with complex index, coherent
    films incl. metals with k <= 5), 6 angles incl. 0° and 89°, 3 wavelengths, s and p, both
    sides: within 1e-9 of tmm.inc_tmm (TIR-aware wrapper) wherever tmm is not clamped."""
    rng = np.random.default_rng(4242)
    err = dict(R_front=0.0, T_front=0.0, R_back=0.0, T_back=0.0, recip=0.0)
    counts = dict(front=0, back=0, clamped=0, tir=0)
    for pattern in PATTERNS:
        items = [_random_mixed(rng, pattern) for _ in range(N_PER_PATTERN)]
        out = _run(items)
        for i, (n, d, c, ang, wl) in enumerate(items):
            for x in out:
                assert np.all(np.isfinite(x[i])), (pattern, n, d)
            rev_n, rev_d, rev_c = n[::-1], d[::-1], c[::-1]
            for ia, th in enumerate(ang):
                s = n[0].real * math.sin(th)
                back = n[-1].imag == 0.0 and s < n[-1].real * (1 - 1e-9)
                if ref.first_evanescent_incoherent(n, c, th) is not None:
                    counts["tir"] += 1
                for iw, lam in enumerate(wl):
                    if ref.tmm_is_clamped(n, d, c, th, lam):
                        counts["clamped"] += 1
                        continue
                    for ip, pol in enumerate("sp"):
                        R, T = ref.inc_stack_R_T(pol, n, d, c, th, lam)
                        err["R_front"] = max(err["R_front"], abs(out.R_front[i, ia, ip, iw] - R))
                        err["T_front"] = max(err["T_front"], abs(out.T_front[i, ia, ip, iw] - T))
                        counts["front"] += 1
                        if back:
                            th_b = snell_angle(n[0].real, n[-1].real, th)
                            if ref.tmm_is_clamped(rev_n, rev_d, rev_c, th_b, lam):
                                continue
                            R, T = ref.inc_stack_R_T(pol, rev_n, rev_d, rev_c, th_b, lam)
                            err["R_back"] = max(err["R_back"], abs(out.R_back[i, ia, ip, iw] - R))
                            err["T_back"] = max(err["T_back"], abs(out.T_back[i, ia, ip, iw] - T))
                            err["recip"] = max(
                                err["recip"], abs(out.T_back[i, ia, ip, iw] - out.T_front[i, ia, ip, iw])
                            )
                            counts["back"] += 1
            assert max(err.values()) <= TOL_TMM, (err, pattern, n, d)
    assert counts["front"] > 3500 and counts["back"] > 2000 and counts["tir"] > 20
    print(f"\ninc/mixed vs tmm: counts {counts}, max errors {err}")


def test_alpha_layers_against_beer_recursion():
    """Layer(n_real, h, coherent=False, alpha=α): Simonot's recursion (tmm-free reference),
    1..4 layers, s, p and natural light, both sides, within 1e-12 — including interior TIR.
    One layer runs in its own shape; 2..4 layers share the 4-layer shape through index-matched
    zero-thickness incoherent padding (an exact no-op)."""
    rng = np.random.default_rng(99)
    worst = 0.0
    n_cases = 0
    groups = {1: [], 4: []}
    for K in (1, 2, 3, 4):
        for _ in range(12):
            n = [float(rng.uniform(1.0, 1.8))] + list(rng.uniform(1.0, 2.4, K)) + [float(rng.uniform(1.0, 2.0))]
            h = list(rng.uniform(1e3, 1e5, K))
            alpha = list(rng.choice([0.0, 1.0], K) * rng.uniform(0.0, 5e-5, K))
            ang = np.deg2rad(np.concatenate([[0.0, 89.0], rng.uniform(0.0, 89.0, N_ANG - 2)]))
            target = 1 if K == 1 else 4
            n_pad, d_pad, _, a_pad = pad_index_matched(
                n, [INF] + h + [INF], target, rng, [False] * K, alpha, pad_coherent=False
            )
            groups[target].append((n, h, alpha, ang, build_stack(n_pad, d_pad, [False] * target, a_pad, leaves=True)))
    for items in groups.values():
        stacks = tree_stack([it[4] for it in items])
        wl = jnp.full((len(items), 2), 550.0).at[:, 1].set(700.0)  # α given: λ plays no role
        out = jax.tree.map(np.asarray, _batched(stacks, wl, jnp.asarray(np.stack([it[3] for it in items]))))
        for i, (n, h, alpha, ang, _) in enumerate(items):
            ah = [a * x for a, x in zip(alpha, h)]
            for ia, th in enumerate(ang):
                for ip, pol in enumerate("sp"):
                    R, T = ref.beer_stack_R_T(pol, n, ah, th)
                    worst = max(worst, max_abs(out.R_front[i, ia, ip], R), max_abs(out.T_front[i, ia, ip], T))
                    s = n[0] * math.sin(th)
                    if s < n[-1] * (1 - 1e-9):
                        Rb, Tb = ref.beer_stack_R_T(pol, n, ah, snell_angle(n[0], n[-1], th), reverse=True)
                        worst = max(worst, max_abs(out.R_back[i, ia, ip], Rb), max_abs(out.T_back[i, ia, ip], Tb))
                # natural light is the mean of the whole-stack s and p (not per interface)
                Ru, Tu = ref.beer_stack_R_T("u", n, ah, th)
                worst = max(worst, abs(out.R_front[i, ia].mean(0)[0] - Ru), abs(out.T_front[i, ia].mean(0)[0] - Tu))
                n_cases += 1
            assert worst <= TOL_BEER, (worst, n, h, alpha)
    assert n_cases == 4 * 12 * N_ANG
    print(f"\nalpha layers vs Beer recursion: max error {worst:.3g}")


def test_alpha_spectrum_and_slanted_path():
    """α given as an array on the wavelength grid; one layer index-matched to both outer media:
    T = exp(-α h / cos θ1) exactly (Beer along the slanted path, Simonot eq. 23), R = 0."""
    wl = jnp.array([400.0, 500.0, 600.0, 700.0])
    alpha = np.array([1e-5, 2e-5, 0.0, 4e-5])
    h = 2e4
    st = ls.Stack(1.5, [ls.Layer(1.5, h, coherent=False, alpha=jnp.asarray(alpha))], ls.Substrate(1.5))
    ang = np.deg2rad([0.0, 30.0, 60.0, 85.0])
    out = ls.specular(st, wl, angle_rad=jnp.asarray(ang))
    expected = np.exp(-alpha[None, :] * h / np.cos(ang)[:, None])
    assert max_abs(out.T_front[:, 0], expected) <= 1e-15 * 10
    assert max_abs(out.T_front[:, 1], expected) <= 1e-15 * 10
    assert max_abs(out.R_front, 0.0) <= 1e-30


def test_reciprocity_and_front_back_asymmetry_of_absorbing_films():
    """T_front == T_back (real outer media) but R_front != R_back when the films absorb
    (Simonot eq. 44, and the coherent-packet generalisation); each side equals tmm."""
    n = [1.0, 1.5, 0.3 + 3.0j, 1.9 + 0.2j, 1.5, 1.33]
    d = [INF, 2e4, 25.0, 60.0, 3e4, INF]
    c = ["i", "i", "c", "c", "i", "i"]
    st = build_stack(n, d, [x == "c" for x in c[1:-1]])
    ang = np.deg2rad([0.0, 25.0, 45.0])
    out = ls.specular(st, jnp.array([450.0, 650.0]), angle_rad=jnp.asarray(ang))
    assert max_abs(out.T_front, out.T_back) <= 1e-14
    assert float(jnp.min(jnp.abs(out.R_front - out.R_back))) > 1e-2
    for ia, th in enumerate(ang):
        th_b = snell_angle(1.0, 1.33, th)
        for iw, lam in enumerate((450.0, 650.0)):
            for ip, pol in enumerate("sp"):
                R, T = ref.inc_stack_R_T(pol, n, d, c, th, lam)
                Rb, Tb = ref.inc_stack_R_T(pol, n[::-1], d[::-1], c[::-1], th_b, lam)
                assert abs(float(out.R_front[ia, ip, iw]) - R) <= TOL_TMM
                assert abs(float(out.R_back[ia, ip, iw]) - Rb) <= TOL_TMM
                assert abs(float(out.T_back[ia, ip, iw]) - Tb) <= TOL_TMM
    # lossless films: R_front == R_back too (energy conservation + reciprocity)
    st = build_stack([1.0, 1.5, 2.1, 1.38, 1.5, 1.33], d, [x == "c" for x in c[1:-1]])
    out = ls.specular(st, jnp.array([450.0, 650.0]), angle_rad=jnp.asarray(ang))
    assert max_abs(out.R_front, out.R_back) <= 1e-13
    assert max_abs(out.R_front + out.T_front, 1.0) <= 1e-13


def test_total_internal_reflection_inside_the_stack():
    """Dense ambient, a low-index thick layer deep inside: past its critical angle T = 0 exactly,
    no NaN, R equals the TIR-aware references (tmm split and Beer recursion); also at the exact
    critical angle of that layer and at 89.9° and 90°."""
    th_c = math.asin(1.0 / 1.6)
    assert 1.6 * math.sin(th_c) == 1.0  # the Snell invariant is exactly the layer's index
    ang = np.array([0.3, th_c - 1e-6, th_c, th_c + 1e-6, 0.9, math.radians(89.9), math.pi / 2])
    wl = jnp.array([500.0, 600.0])
    # (a) α-layers, real indices: 1.6 | 1.7 (α) | 1.0 (α) | 1.5 (α) | 1.5
    n = [1.6, 1.7, 1.0, 1.5, 1.5]
    h = [2e4, 1e4, 3e4]
    alpha = [1e-5, 2e-5, 1e-5]
    out = ls.specular(build_stack(n, [INF] + h + [INF], [False] * 3, alpha), wl, angle_rad=jnp.asarray(ang))
    for x in out:
        assert np.all(np.isfinite(np.asarray(x)))
    ah = [a * x for a, x in zip(alpha, h)]
    for ia, th in enumerate(ang):
        for ip, pol in enumerate("sp"):
            R, T = ref.beer_stack_R_T(pol, n, ah, th)
            assert max_abs(out.R_front[ia, ip], R) <= TOL_BEER, (th, pol)
            assert max_abs(out.T_front[ia, ip], T) <= TOL_BEER
    assert np.all(np.asarray(out.T_front[ang >= th_c]) == 0.0)
    # (b) complex thick layers and a coherent film before the evanescent thick layer
    n = [1.6, 1.7 + 1e-5j, 2.0 + 0.5j, 1.0, 1.5 + 1e-5j, 1.5]
    d = [INF, 2e4, 40.0, 3e4, 1e4, INF]
    c = ["i", "i", "c", "i", "i", "i"]
    out = ls.specular(build_stack(n, d, [x == "c" for x in c[1:-1]]), wl, angle_rad=jnp.asarray(ang))
    for x in out:
        assert np.all(np.isfinite(np.asarray(x)))
    assert np.all(np.asarray(out.T_front[ang >= th_c]) == 0.0)
    for ia, th in enumerate(ang):
        if abs(th - th_c) < 1e-3:
            continue  # tmm itself is unreliable within 1e-6 rad of the branch point
        for iw, lam in enumerate((500.0, 600.0)):
            for ip, pol in enumerate("sp"):
                R, T = ref.inc_stack_R_T(pol, n, d, c, th, lam)
                assert abs(float(out.R_front[ia, ip, iw]) - R) <= TOL_TMM, (th, lam, pol)
                assert abs(float(out.T_front[ia, ip, iw]) - T) <= TOL_TMM
    # 90°: nothing enters
    assert max_abs(out.R_front[-1], 1.0) <= 1e-15 and np.all(np.asarray(out.T_front[-1]) == 0.0)


def test_frustrated_tir_through_a_thin_film_between_thick_layers():
    """A thin low-index coherent film between thick layers tunnels past its critical angle
    (T > 0), unlike a thick layer of the same index (T = 0)."""
    th = 0.9  # 1.5 sin 0.9 = 1.175 > 1.0
    n = [1.5, 1.5, 1.0, 1.5, 1.5]
    for kind, dd, cc in (("thin", 100.0, "c"), ("thick", 1e5, "i")):
        d = [INF, 1e4, dd, 1e4, INF]
        c = ["i", "i", cc, "i", "i"]
        out = ls.specular(build_stack(n, d, [x == "c" for x in c[1:-1]]), jnp.array([500.0]), angle_rad=th)
        for ip, pol in enumerate("sp"):
            R, T = ref.inc_stack_R_T(pol, n, d, c, th, 500.0)
            assert abs(float(out.R_front[ip, 0]) - R) <= TOL_TMM
            assert abs(float(out.T_front[ip, 0]) - T) <= TOL_TMM
            assert (float(out.T_front[ip, 0]) > 1e-3) if kind == "thin" else (float(out.T_front[ip, 0]) == 0.0)


def test_opaque_thick_layer_no_nan_and_limits():
    """A thick layer with huge absorption: T = 0 (no NaN, no 0 * inf), R = front interface."""
    for layer in (
        ls.Layer(1.5, 1e6, coherent=False, alpha=1.0),
        ls.Layer(ls.Index(1.5, 0.5), 1e6, coherent=False),
    ):
        st = ls.Stack(1.0, [layer], ls.Substrate(1.5))
        ang = np.deg2rad([0.0, 45.0, 89.9])
        out = ls.specular(st, jnp.array([500.0]), angle_rad=jnp.asarray(ang))
        for x in out:
            assert np.all(np.isfinite(np.asarray(x)))
        assert np.all(np.asarray(out.T_front) == 0.0)
        n1 = complex(layer.index(500.0))
        if n1.imag == 0:
            Rs, Rp, _ = ref.fresnel_natural_R(1.0, 1.5, ang)
            assert max_abs(out.R_front[:, 0, 0], Rs) <= 1e-13
            assert max_abs(out.R_front[:, 1, 0], Rp) <= 1e-13
        else:
            for ia, th in enumerate(ang):
                for ip, pol in enumerate("sp"):
                    R, _ = ref.coh_stack_R_T(pol, [1.0, n1], [INF, INF], th, 500.0)
                    assert abs(float(out.R_front[ia, ip, 0]) - R) <= 1e-13


@pytest.mark.slow
def test_mixed_stacks_many_more():
    """Exhaustive version: 10x the random mixed stacks."""
    rng = np.random.default_rng(77)
    for pattern in PATTERNS_ALL:
        items = [_random_mixed(rng, pattern) for _ in range(5 * N_PER_PATTERN)]
        out = _run(items)
        for i, (n, d, c, ang, wl) in enumerate(items):
            for ia, th in enumerate(ang):
                for iw, lam in enumerate(wl):
                    if ref.tmm_is_clamped(n, d, c, th, lam):
                        continue
                    for ip, pol in enumerate("sp"):
                        R, T = ref.inc_stack_R_T(pol, n, d, c, th, lam)
                        assert abs(out.R_front[i, ia, ip, iw] - R) <= TOL_TMM
                        assert abs(out.T_front[i, ia, ip, iw] - T) <= TOL_TMM
