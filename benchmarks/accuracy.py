"""ACCURACY: diffuse-reflectance quadrature error against total node count.

    python -m benchmarks._sections ACCURACY --out acc.json [--quick]

Two rules, same integrand (natural-light reflectance in μ = sin²θ of the integration medium,
Simonot eqs. 18, 47, 62):

* the library's default rule, called through the public ``layerstack_jax.diffuse(stack, wl, side,
  nodes=N)`` (``N`` nodes per segment; today: split at the critical angles + end-point map), so
  the figures follow whatever rule ``_quadrature.py`` ships; the total node count is read from
  the public ``layerstack_jax.hemispherical_rule`` (falls back to N × segments if its
  signature changes);
* plain Gauss–Legendre over μ ∈ [0, 1] (``_quadrature.plain_gauss_legendre_rule``), the
  integrand evaluated with the public ``layerstack_jax.specular``.

Cases, each against a reference that shares no code with the library:

* ``glass``: internal diffuse reflectance of glass n = 1.5 (light from the glass side of one
  interface with air), closed form 0.596345759708 (PHYSICS.md, trap 4), evaluated to full
  precision by ``tests/reference.diffuse_interface_closed`` (Stern/Judd formula);
* ``P2``: back-side r of the P2 stack (3 absorbing incoherent layers, 580 nm) against
  ``tests/reference.diffuse_beer_stack`` (independent numpy Beer recursion + scipy quad);
* ``P3``: back-side r of the P3 stack (2 films on an absorbing varnish, 550 nm) against
  ``tests/reference.diffuse_stack_reference`` (tmm.inc_tmm + scipy quad).

Writes ``quadrature_accuracy.png``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from ._sections import figure, save, setup_jax

GLASS_EXACT = 0.596345759708  # internal diffuse reflectance of n = 1.5 (12 digits; checked against the formula)
PER_SEGMENT_FULL = (2, 4, 8, 12, 16, 24, 32)
PLAIN_FULL = (4, 8, 16, 32, 64, 128, 256, 512, 1024, 2048)
PER_SEGMENT_QUICK = (8, 24)
PLAIN_QUICK = (16, 256)


def _ref():
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    import reference

    return reference


def cases():
    """name -> (forward stack, reversed stack for the plain rule, wavelength nm, reference thunk, label)."""
    import layerstack_jax as ls

    from . import mixed
    from .radiometric import build

    out = {}
    out["glass"] = (ls.Stack(1.0, [], ls.Substrate(1.5)), ls.Stack(1.5, [], ls.Substrate(1.0)), 550.0,
                    lambda: _ref().diffuse_interface_closed(1.5, 1.0), "glass n=1.5, internal (closed form, Judd/Stern)")

    # P2 at 580 nm, sample 0 of radiometric.run (same rng), back side (from the background's binder)
    _, wl, alpha, rho, indices = build(ls.DEFAULT_NODES, None)
    i = int(np.argmin(np.abs(np.asarray(wl) - 580.0)))
    h = np.random.default_rng(0).uniform(2e3, 3e4, (1, 3))[0]
    a = [float(np.asarray(alpha[j])[i]) for j in range(3)]
    layers = [ls.Layer(n, hh, coherent=False, alpha=aa) for n, hh, aa in zip(indices, h, a)]
    fwd = ls.Stack(1.0, layers, ls.Substrate(1.52))
    rev = ls.Stack(1.52, layers[::-1], ls.Substrate(1.0))
    n_list = [1.0, *indices, 1.52]
    ah = [a[j] * h[j] for j in range(3)]
    out["P2"] = (fwd, rev, float(np.asarray(wl)[i]),
                 lambda: _ref().diffuse_beer_stack(n_list, ah, side="back")[0], "P2 back side, 580 nm (Beer + scipy quad)")

    # P3 at 550 nm, sample 0 of mixed.samples
    h3 = mixed.samples(1)[0]
    lam = 550.0
    k = float(mixed.alpha_varnish(lam) * lam / (4 * np.pi))
    films = [ls.Layer(mixed.N_FILM[0], h3[0]), ls.Layer(mixed.N_FILM[1], h3[1])]
    varnish = ls.Layer(ls.Index(mixed.N_VARNISH, k), h3[2], coherent=False)
    fwd3 = ls.Stack(1.0, [*films, varnish], ls.Substrate(mixed.N_BACKGROUND))
    rev3 = ls.Stack(mixed.N_BACKGROUND, [varnish, *films[::-1]], ls.Substrate(1.0))
    n3 = [1.0, *mixed.N_FILM, mixed.N_VARNISH + 1j * k, mixed.N_BACKGROUND]
    d3 = [np.inf, h3[0], h3[1], h3[2], np.inf]
    c3 = ["i", "c", "c", "i", "i"]
    out["P3"] = (fwd3, rev3, lam, lambda: _ref().diffuse_stack_reference(n3, d3, c3, lam, side="back")[0],
                 "P3 back side, 550 nm (tmm.inc_tmm + scipy quad)")
    return out


def total_nodes(stack, side: str, per_segment: int) -> int:
    """Total nodes the default rule spends on this stack (public ``hemispherical_rule``)."""
    import layerstack_jax as ls

    n = [np.real(stack.ambient(np.array([550.0]))), *(l.index(np.array([550.0])) for l in stack.layers),
         np.real(stack.exit.index(np.array([550.0])))]
    n_from, others = (n[0], n[1:]) if side == "front" else (n[-1], n[:-1])
    try:
        mu, _ = ls.hemispherical_rule(np.atleast_1d(n_from), others, per_segment)
        return int(mu.shape[0])
    except Exception:  # rule changed shape or signature: count segments by critical angles
        seg = 1 + len({float(np.real(x[0])) for x in others if np.real(x[0]) < np.real(n_from[0])})
        return per_segment * seg


def default_rule(stack, lam: float, per_segment: int) -> float:
    """``ls.diffuse(stack, [lam], 'back', nodes=per_segment).r``, jitted (one compile per N)."""
    import jax
    import jax.numpy as jnp

    import layerstack_jax as ls

    return float(jax.jit(lambda: ls.diffuse(stack, jnp.asarray([lam]), "back", nodes=per_segment).r[0])())


def plain_rule(reversed_stack, lam: float, totals) -> list[float]:
    """Plain Gauss–Legendre in μ for each total node count; the integrand (natural-light R from
    ``ls.specular`` of the reversed stack) is evaluated at all rules' nodes in one jitted call."""
    import jax
    import jax.numpy as jnp

    import layerstack_jax as ls
    from layerstack_jax._kernels.quadrature import plain_gauss_legendre_rule

    rules = [plain_gauss_legendre_rule(int(n)) for n in totals]
    theta = np.arcsin(np.sqrt(np.concatenate([mu for mu, _ in rules])))
    R = jax.jit(lambda th: ls.specular(reversed_stack, jnp.asarray([lam]), angle_rad=th, both_sides=False).natural().R_front[:, 0])
    R = np.asarray(R(jnp.asarray(theta)))
    out, start = [], 0
    for mu, w in rules:
        out.append(float(np.sum(w * R[start:start + mu.size])))
        start += mu.size
    return out


def run(quick: bool = False, out_dir=None) -> dict:
    setup_jax(True)
    per_seg = PER_SEGMENT_QUICK if quick else PER_SEGMENT_FULL
    plain = PLAIN_QUICK if quick else PLAIN_FULL
    res: dict = {"cases": {}}
    for name, (fwd, rev, lam, ref_fn, label) in cases().items():
        if quick and name != "glass":
            continue
        exact = float(ref_fn())
        if name == "glass" and abs(exact - GLASS_EXACT) > 1e-12:
            raise RuntimeError(f"closed form {exact} disagrees with {GLASS_EXACT}")
        rows = []
        for N in per_seg:
            rows.append({"rule": "default", "per_segment": N, "total_nodes": total_nodes(fwd, "back", N),
                         "abs_err": abs(default_rule(fwd, lam, N) - exact)})
        for N, value in zip(plain, plain_rule(rev, lam, plain)):
            rows.append({"rule": "plain Gauss-Legendre", "per_segment": None, "total_nodes": N,
                         "abs_err": abs(value - exact)})
        res["cases"][name] = {"label": label, "wavelength_nm": lam, "reference": exact, "rows": rows}
    if out_dir is not None:
        fig = figure(6.4, 4.4)
        ax = fig.subplots()
        for (name, c), color in zip(res["cases"].items(), ("C0", "C1", "C2")):
            for rule, style in (("default", "o-"), ("plain Gauss-Legendre", "s--")):
                rr = [r for r in c["rows"] if r["rule"] == rule]
                ax.plot([r["total_nodes"] for r in rr], [max(r["abs_err"], 1e-17) for r in rr], style, color=color,
                        label=f"{name}: {'default rule' if rule == 'default' else 'plain GL'}")
        ax.set(xscale="log", yscale="log", xlabel="total quadrature nodes", ylabel="|r − reference|",
               title="diffuse reflectance: quadrature error vs cost")
        ax.axhline(1e-10, color="gray", lw=0.6)
        ax.legend(fontsize=7)
        res["plot"] = save(fig, Path(out_dir) / "quadrature_accuracy.png")
    return res


def markdown(r: dict) -> list[str]:
    lines = ["Diffuse reflectance (back side) by the library's default rule, called as "
             "`ls.diffuse(stack, wl, 'back', nodes=N)` (N per segment), and by plain Gauss–Legendre in μ; "
             "|error| against a reference that shares no code with the library (errors below ~1e-15 are rounding).", ""]
    for name, c in r["cases"].items():
        lines += [f"**{name}** — {c['label']}: reference r = {c['reference']:.12f}", "",
                  "| rule | nodes / segment | total nodes | abs error |", "|---|---|---|---|"]
        for x in c["rows"]:
            lines.append(f"| {x['rule']} | {x['per_segment'] or '—'} | {x['total_nodes']} | {x['abs_err']:.1e} |")
        lines.append("")
    if r.get("plot"):
        lines.append(f"![quadrature accuracy]({r['plot']})")
    return lines
