"""Timing of the Mitsuba 3 coated-surface plugin, vectorized (llvm) against scalar (standalone; needs
the `render` extra).

    python -m benchmarks.render_mitsuba [--size 256x256] [--spp 16] [--sigma 25]
                                        [--panel 512x384 --panel-spp 256] [--no-scalar]

Renders the Fig. 8 pair of Hirayama et al. (Al spheres, the left one coated with dielectric A
1000 nm / Ag 5 nm / dielectric A 1000 nm, the right one bare; He–Torrance roughness σ0 nm,
τ = 300 nm; the scene of ``layerstack_jax.render._scenes.fig8_scene``) at the same size and
samples per pixel in ``scalar_spectral`` and in ``llvm_ad_spectral``, in one process, and
reports: the time to build the tables, each variant's render time (llvm: the first render,
which compiles the kernels, and a second one with the kernels cached), the time spent in the
scalar plugin's Python methods (each call timed), the speed-up, the same scene with Mitsuba's
built-in C++ ``roughconductor`` on both spheres in llvm as what the rest of the renderer costs,
and the time of one Fig. 8 panel at the notebook's final resolution and samples per pixel
(``--panel``, llvm). The scene is the notebook's: stratified samples (``multijitter``), the
lamp's spectrum in the sensor's response (``_scenes.camera``). The load average is read before and after. Results:
``benchmarks/results/render_mitsuba.{json,md}``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import layerstack_jax as ls  # noqa: E402

RESULTS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results")


def fig8_tables(wl, sigma_nm):
    from layerstack_jax._appearance.render_tables import coating_tables

    def on_grid(book, source):
        n = np.asarray(ls.material(book, source)(wl))
        return ls.Index(n.real, n.imag)

    silver, aluminium = on_grid("Ag", "Johnson"), on_grid("Al", "Rakic")
    coated = ls.Stack(1.0, [ls.Layer(1.4, 1000.0), ls.Layer(silver, 5.0), ls.Layer(1.4, 1000.0)], ls.Substrate(aluminium))
    bare = ls.Stack(1.0, [], ls.Substrate(aluminium))
    options = dict(n_angles=46, n_angles_out=16, n_phi=9, sigma_nm=sigma_nm, tau_nm=300.0, estimate_error=False,
                   include_diffuse=sigma_nm > 0)
    return coating_tables(coated, wl, **options), coating_tables(bare, wl, **options)


def _size(text):
    w, h = text.lower().split("x")
    return int(w), int(h)


def _render(mi, dr, scene, spp, seed=0):
    t0 = time.perf_counter()
    img = mi.render(scene, seed=seed, spp=spp)
    dr.eval(img)
    dr.sync_thread()
    out = np.array(img)
    return time.perf_counter() - t0, out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=_size, default=(256, 256), help="WxH of the scalar-vs-llvm comparison")
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--sigma", type=float, default=25.0, help="rms roughness σ0 in nm (0: smooth)")
    parser.add_argument("--panel", type=_size, default=(512, 384), help="WxH of one final Fig. 8 panel (llvm)")
    parser.add_argument("--panel-spp", type=int, default=256)
    parser.add_argument("--no-scalar", action="store_true", help="skip the (slow) scalar render")
    parser.add_argument("--out", default=RESULTS)
    args = parser.parse_args(argv)

    from layerstack_jax.render import coated_bsdf
    from layerstack_jax.render._llvm import llvm_problem
    from layerstack_jax.render._scenes import fig8_scene

    problem = llvm_problem()
    if problem:
        raise SystemExit(problem)
    import drjit as dr
    import mitsuba as mi

    load = [os.getloadavg()]
    wl = np.arange(380.0, 781.0, 10.0)
    t0 = time.perf_counter()
    coated_t, bare_t = fig8_tables(wl, args.sigma)
    t_tables = time.perf_counter() - t0
    W, H = args.size
    res: dict = {"machine": platform.processor() or platform.machine(), "cpus": os.cpu_count(), "mitsuba": mi.__version__,
                 "drjit": dr.__version__, "sigma_nm": args.sigma, "size": [W, H], "spp": args.spp, "tables_s": t_tables,
                 "llvm": os.environ.get("DRJIT_LIBLLVM_PATH")}

    # llvm: first render compiles the kernels, the second reuses them
    mi.set_variant("llvm_ad_spectral")
    scene = mi.load_dict(fig8_scene(coated_bsdf(coated_t), coated_bsdf(bare_t), width=W, height=H, spp=args.spp))
    res["llvm_first_s"], img_llvm = _render(mi, dr, scene, args.spp, seed=0)
    res["llvm_s"], _ = _render(mi, dr, scene, args.spp, seed=1)
    builtin = {"type": "roughconductor", "material": "Al", "alpha": 0.1} if args.sigma > 0 else {"type": "conductor", "material": "Al"}
    scene_b = mi.load_dict(fig8_scene(builtin, builtin, width=W, height=H, spp=args.spp))
    _render(mi, dr, scene_b, args.spp)
    res["llvm_builtin_s"], _ = _render(mi, dr, scene_b, args.spp, seed=1)
    # one final panel
    PW, PH = args.panel
    scene_p = mi.load_dict(fig8_scene(coated_bsdf(coated_t), coated_bsdf(bare_t), width=PW, height=PH, spp=args.panel_spp))
    res["panel"] = {"size": [PW, PH], "spp": args.panel_spp}
    res["panel"]["s"], _ = _render(mi, dr, scene_p, args.panel_spp, seed=0)  # compiles its kernels too (~2 s)
    load.append(os.getloadavg())

    if not args.no_scalar:
        mi.set_variant("scalar_spectral")
        timings: dict = {}
        scene_s = mi.load_dict(fig8_scene(coated_bsdf(coated_t, timings=timings), coated_bsdf(bare_t, timings=timings),
                                          width=W, height=H, spp=args.spp))
        res["scalar_s"], img_scalar = _render(mi, dr, scene_s, args.spp, seed=0)
        res["scalar_plugin_s"] = sum(v[0] for v in timings.values())
        res["scalar_plugin_calls"] = sum(v[1] for v in timings.values())
        res["speedup"] = res["scalar_s"] / res["llvm_s"]
        res["speedup_with_compile"] = res["scalar_s"] / res["llvm_first_s"]
        res["mean_llvm_over_scalar"] = float(img_llvm.mean() / img_scalar.mean())
        load.append(os.getloadavg())
    res["load"] = load

    lines = [
        f"# Mitsuba plugin: llvm_ad_spectral vs scalar_spectral (Fig. 8 rough pair, issue 29)",
        "",
        f"`python -m benchmarks.render_mitsuba` at {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; "
        f"{res['machine']}, {res['cpus']} CPUs, Mitsuba {res['mitsuba']}, Dr.Jit {res['drjit']} (LLVM: {res['llvm']}); "
        f"load average (1/5/15 min) before / after llvm / after scalar: "
        + "; ".join("/".join(f"{x:.1f}" for x in l) for l in load),
        "",
        f"Fig. 8 pair (Al + A/Ag/A beside bare Al, σ0 = {args.sigma:g} nm, τ = 300 nm), tables 46 × 16 × 9 × 41 λ built in "
        f"{t_tables:.1f} s.",
        "",
        "| render | size | spp | time |",
        "| --- | --- | --- | --- |",
    ]
    if "scalar_s" in res:
        lines.append(f"| scalar_spectral, coated plugin | {W}×{H} | {args.spp} | {res['scalar_s']:.1f} s "
                     f"({100 * res['scalar_plugin_s'] / res['scalar_s']:.0f} % in the plugin, {res['scalar_plugin_calls']} calls) |")
    lines += [
        f"| llvm_ad_spectral, coated plugin, first render (compiles) | {W}×{H} | {args.spp} | {res['llvm_first_s']:.2f} s |",
        f"| llvm_ad_spectral, coated plugin, kernels cached | {W}×{H} | {args.spp} | {res['llvm_s']:.2f} s |",
        f"| llvm_ad_spectral, built-in {builtin['type']} on both spheres | {W}×{H} | {args.spp} | {res['llvm_builtin_s']:.2f} s |",
        f"| llvm_ad_spectral, one final Fig. 8 panel (with its kernels' compilation) | {PW}×{PH} | {args.panel_spp} | "
        f"{res['panel']['s']:.1f} s |",
    ]
    if "scalar_s" in res:
        lines += ["", f"**Speed-up llvm / scalar: {res['speedup']:.0f}×** (kernels cached; {res['speedup_with_compile']:.0f}× "
                  f"counting the first render's compilation). Image means agree: llvm / scalar = {res['mean_llvm_over_scalar']:.4f} "
                  "(different random streams)."]
    text = "\n".join(lines) + "\n"
    print(text)
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, "render_mitsuba.json"), "w") as f:
        json.dump(res, f, indent=1)
    with open(os.path.join(args.out, "render_mitsuba.md"), "w") as f:
        f.write(text)


if __name__ == "__main__":
    main()
