"""Timing of the Mitsuba 3 coated-surface plugin (standalone; needs the `render` extra).

    python benchmarks/render_mitsuba.py [--size 256] [--spp 16] [--sigma 25]

Renders the Fig. 8 pair of Hirayama et al. (Al spheres, the left one coated with
dielectric A 1000 nm / Ag 5 nm / dielectric A 1000 nm, the right one bare; He–Torrance roughness
σ0 nm, τ = 300 nm) at size × size pixels and spp samples per pixel in ``scalar_spectral``, and
reports: the time to build the tables (``coating_tables``), the render time, the time spent in
the plugin's Python methods (each call timed: ``coated_bsdf(..., timings=)``) and its share, and
the same scene with Mitsuba's built-in C++ ``roughconductor``/``conductor`` on both spheres as a
baseline of what the rest of the renderer costs.
"""

from __future__ import annotations

import argparse
import platform
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import layerstack_jax as ls  # noqa: E402


def fig8_tables(wl, sigma_nm):
    from layerstack_jax._render_tables import coating_tables

    def on_grid(book, source):
        n = np.asarray(ls.material(book, source)(wl))
        return ls.Index(n.real, n.imag)

    silver, aluminium = on_grid("Ag", "Johnson"), on_grid("Al", "Rakic")
    coated = ls.Stack(1.0, [ls.Layer(1.4, 1000.0), ls.Layer(silver, 5.0), ls.Layer(1.4, 1000.0)], ls.Substrate(aluminium))
    bare = ls.Stack(1.0, [ls.Layer(1.4, 0.0), ls.Layer(silver, 0.0), ls.Layer(1.4, 0.0)], ls.Substrate(aluminium))
    options = dict(n_angles=46, n_angles_out=16, n_phi=9, sigma_nm=sigma_nm, tau_nm=300.0, estimate_error=False,
                   include_diffuse=sigma_nm > 0)
    return coating_tables(coated, wl, **options), coating_tables(bare, wl, **options)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--sigma", type=float, default=25.0, help="rms roughness σ0 in nm (0: smooth)")
    args = parser.parse_args(argv)

    import mitsuba as mi

    from layerstack_jax.render import coated_bsdf
    from layerstack_jax.render._scenes import fig8_scene

    mi.set_variant("scalar_spectral")
    wl = np.arange(380.0, 781.0, 10.0)
    t0 = time.perf_counter()
    coated_t, bare_t = fig8_tables(wl, args.sigma)
    t_tables = time.perf_counter() - t0

    timings: dict = {}
    coated = coated_bsdf(coated_t, timings=timings)
    bare = coated_bsdf(bare_t, timings=timings)
    scene = mi.load_dict(fig8_scene(coated, bare, width=args.size, height=args.size, spp=args.spp))
    t0 = time.perf_counter()
    mi.render(scene, seed=0)
    t_render = time.perf_counter() - t0
    t_plugin = sum(v[0] for v in timings.values())
    calls = sum(v[1] for v in timings.values())

    builtin = {"type": "roughconductor", "material": "Al", "alpha": 0.1} if args.sigma > 0 else {"type": "conductor", "material": "Al"}
    scene_c = mi.load_dict(fig8_scene(builtin, builtin, width=args.size, height=args.size, spp=args.spp))
    t0 = time.perf_counter()
    mi.render(scene_c, seed=0)
    t_builtin = time.perf_counter() - t0

    print(f"machine: {platform.processor() or platform.machine()}, mitsuba {mi.__version__}, variant scalar_spectral")
    print(f"Fig. 8 pair (Al + A/Ag/A, sigma0 = {args.sigma:g} nm, tau = 300 nm), {args.size}x{args.size} px, {args.spp} spp")
    print(f"tables (2 coatings, {wl.size} wavelengths): {t_tables:.1f} s")
    print(f"render: {t_render:.1f} s; in the plugin: {t_plugin:.1f} s ({100 * t_plugin / t_render:.0f} %), "
          f"{calls} calls, {1e6 * t_plugin / max(calls, 1):.1f} us per call")
    for name, (sec, n) in sorted(timings.items()):
        print(f"  {name:9s} {n:9d} calls  {sec:7.2f} s  {1e6 * sec / max(n, 1):6.1f} us/call")
    print(f"same scene with Mitsuba's built-in C++ {builtin['type']}: {t_builtin:.1f} s")


if __name__ == "__main__":
    main()
