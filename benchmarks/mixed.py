"""P3 (mixed stack): two coherent films on an absorbing incoherent varnish over a Lambertian background.

    python -m benchmarks._sections P3 --out p3.json [--quick]

Stack, from the air side: TiO2-like film (n = 2.3, d1) · SiO2-like film (n = 1.46, d2) · varnish
(n = 1.6 + ik, k = αλ/4π with α(λ) ≈ 2e-5 /nm, thickness h, incoherent) · Lambertian background
(n_g = 1.55, ρg(λ) a smooth bump); 401 wavelengths 380–780 nm; 45°/0° radiance factor
(``layerstack_jax.Directional(45, 0)``, Simonot eq. 79 with the film packet as one interface).
A batch of samples, each with its own (d1, d2, h), is evaluated by ``jax.lax.map`` over vmapped
blocks (``batch_size=BLOCK``), jitted — what a user predicting many spectra writes.

Timed: the batched forward (spectra/s), value-and-gradient of a least-squares loss w.r.t. the
three thicknesses (reverse mode, ``jax.value_and_grad``) and the Jacobian (``jax.jacfwd``, what a
Levenberg–Marquardt step needs), each relative to the forward.

Checked on a subset against independent references (tests/reference.py, no layerstack code):
the 45°/0° value against ``background_radiance_factor`` (tmm.inc_tmm for T(45°), T(0°) and a
scipy-quad hemispherical integral of tmm.inc_tmm for r_b), and the specular reflectance at 45°
(``layerstack_jax.specular``) against ``tmm.inc_tmm`` directly.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from ._sections import contention_note, setup_jax, timed

N_FILM = (2.3, 1.46)
N_VARNISH = 1.6
N_BACKGROUND = 1.55
WAVELENGTHS = (380.0, 780.0, 401)
BLOCK = 8  # samples per vmapped block inside lax.map
BATCH = {"full": 200, "quick": 16}
SEED = 20240603


def alpha_varnish(wl):
    """Varnish absorption coefficient, 1/nm (yellowish: stronger in the blue)."""
    return 2e-5 * (1.0 + 2.0 * np.exp(-((np.asarray(wl) - 380.0) / 60.0) ** 2))


def rho_background(wl):
    return 0.25 + 0.5 * np.exp(-(((np.asarray(wl) - 600.0) / 90.0) ** 2))


def samples(batch: int, seed: int = SEED) -> np.ndarray:
    """(batch, 3) thicknesses d1, d2, h in nm."""
    rng = np.random.default_rng(seed)
    return np.stack([rng.uniform(40, 120, batch), rng.uniform(60, 200, batch), rng.uniform(5e3, 3e4, batch)], axis=1)


def build(wl, dtype=None):
    """``model(h3) -> (wl,)`` 45°/0° radiance factor, and ``specular(h3) -> (wl,)`` R at 45°."""
    import jax.numpy as jnp

    import layerstack_jax as ls

    wl = jnp.asarray(wl, dtype)
    k = jnp.asarray(alpha_varnish(np.asarray(wl)) * np.asarray(wl) / (4 * np.pi), dtype)
    rho = jnp.asarray(rho_background(np.asarray(wl)), dtype)

    def stack(h):
        return ls.Stack(
            1.0,
            [ls.Layer(N_FILM[0], h[0]), ls.Layer(N_FILM[1], h[1]),
             ls.Layer(ls.Index(N_VARNISH, k), h[2], coherent=False)],
            ls.LambertianBackground(N_BACKGROUND, rho),
        )

    def model(h):
        return ls.reflectance(stack(h), wl, ls.Directional(45.0, 0.0))

    def specular(h):
        return ls.specular(stack(h), wl, angle_rad=jnp.deg2rad(45.0), both_sides=False).natural().R_front

    return model, specular, wl


def reference_values(h, wl_nm):
    """(radiance factor 45/0, specular R at 45°) from tests/reference.py (tmm + scipy quad)."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    import reference as ref

    k = alpha_varnish(wl_nm) * wl_nm / (4 * np.pi)
    n_list = [1.0, N_FILM[0], N_FILM[1], N_VARNISH + 1j * k, N_BACKGROUND]
    d_list = [np.inf, h[0], h[1], h[2], np.inf]
    c_list = ["i", "c", "c", "i", "i"]
    rf = ref.background_radiance_factor(n_list, d_list, c_list, wl_nm, float(rho_background(wl_nm)), np.deg2rad(45.0), 0.0)
    rs = ref.inc_stack_R_T("u", n_list, d_list, c_list, np.deg2rad(45.0), wl_nm)[0]
    return rf, rs


def check(model, specular, wl, H, n_samples: int, n_wl: int) -> dict:
    """Max |Δ| of the 45/0 value and of specular R(45°) against the references on a subset."""
    idx = np.unique(np.round(np.linspace(0, len(wl) - 1, n_wl)).astype(int))
    d_rf = d_rs = 0.0
    for h in np.asarray(H)[:n_samples]:
        ours = np.asarray(model(h))
        ours_s = np.asarray(specular(h))
        for i in idx:
            rf, rs = reference_values(h, float(wl[i]))
            d_rf = max(d_rf, abs(float(ours[i]) - rf))
            d_rs = max(d_rs, abs(float(ours_s[i]) - rs))
    return {"points": int(min(n_samples, len(H)) * len(idx)), "max_abs_err_45_0": d_rf, "max_abs_err_specular45": d_rs}


def run(quick: bool = False, out_dir=None, batch: int | None = None, block: int = BLOCK,
        n_wavelengths: int = WAVELENGTHS[2], check_points: tuple[int, int] | None = None) -> dict:
    """Time P3 and check it on a subset; ``check_points`` = (samples, wavelengths) checked
    against the references (default (2, 6), quick (1, 2); (0, 0) skips the check)."""
    jax = setup_jax(True)
    import jax.numpy as jnp

    wl = np.linspace(WAVELENGTHS[0], WAVELENGTHS[1], n_wavelengths)
    model, specular, wl_j = build(wl)
    batch = batch or BATCH["quick" if quick else "full"]
    H = jnp.asarray(samples(batch))
    data = model(H[0] * 1.03)

    def loss(h):
        return jnp.sum((model(h) - data) ** 2)

    fwd = jax.jit(lambda H: jax.lax.map(model, H, batch_size=block))
    vg = jax.jit(lambda H: jax.lax.map(jax.value_and_grad(loss), H, batch_size=block))
    jac = jax.jit(lambda H: jax.lax.map(jax.jacfwd(model), H, batch_size=block))

    out = {"case": "P3", "batch": batch, "block": block, "wavelengths": len(wl), "dtype": "float64",
           "geometry": "Directional(45, 0)", "nodes_per_segment": None}
    import layerstack_jax as ls

    out["nodes_per_segment"] = ls.DEFAULT_NODES
    rows = []
    for name, fn in (("forward", fwd), ("value_and_grad", vg), ("jacfwd", jac)):
        t, res = timed(fn, H, quick=quick)
        t["spectra_per_s"] = batch / t["min_s"]
        leaves = jax.tree_util.tree_leaves(res)
        t["finite"] = bool(all(np.all(np.isfinite(np.asarray(x))) for x in leaves))
        out[name] = t
        rows.append((f"P3/{name}", t["foreign_cpu_frac"]))
    for name in ("value_and_grad", "jacfwd"):
        out[name]["ratio_to_forward"] = out[name]["min_s"] / out["forward"]["min_s"]
    ns, nw = check_points or ((1, 2) if quick else (2, 6))
    out["reference_check"] = check(model, specular, wl, H, n_samples=ns, n_wl=nw) if ns and nw else None
    out["contention"] = contention_note(rows)
    return out


def markdown(r: dict) -> list[str]:
    f, vg, jf = r["forward"], r["value_and_grad"], r["jacfwd"]
    c = r["reference_check"] or {"points": 0, "max_abs_err_45_0": float("nan"), "max_abs_err_specular45": float("nan")}
    lines = [
        f"Two coherent films (n = {N_FILM[0]}, {N_FILM[1]}) on an absorbing incoherent varnish (n = {N_VARNISH} + ik) "
        f"over a Lambertian background (n_g = {N_BACKGROUND}), 45°/0° radiance factor, {r['wavelengths']} λ, "
        f"batch {r['batch']} (each sample its own d1, d2, h), `jax.lax.map` over vmapped blocks of {r['block']}, "
        f"{r['dtype']}, {r['nodes_per_segment']} nodes/segment.",
        "",
        "| quantity | min (s) | median (s) | spectra/s | / forward | compile (s) | foreign CPU |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, t in (("forward", f), ("value + gradient (reverse, 3 thicknesses)", vg), ("Jacobian (jacfwd, 401 × 3)", jf)):
        lines.append(f"| {name} | {t['min_s']:.3g} | {t['median_s']:.3g} | {t['spectra_per_s']:.0f} | "
                     f"{t.get('ratio_to_forward', 1.0):.2f} | {t['compile_s']:.2f} | {100 * (t['foreign_cpu_frac'] or 0):.0f}% |")
    lines += ["", f"Reference check on {c['points']} (sample, λ) points: max |Δ| of the 45°/0° value vs "
              f"tmm.inc_tmm + scipy quad (tests/reference.py `background_radiance_factor`) = {c['max_abs_err_45_0']:.1e}; "
              f"max |Δ| of specular R(45°) vs tmm.inc_tmm = {c['max_abs_err_specular45']:.1e}."]
    if r.get("contention"):
        lines.append(f"**{r['contention']}**")
    return lines
