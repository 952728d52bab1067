r"""Roofline of the coherent kernel (issue 19): P1's work per layer-point, this machine's
ceilings, and where the time goes.

``python -m benchmarks.roofline [--repeats 7] [--out-dir benchmarks/results]`` writes
``roofline.md`` / ``roofline.json``.

What is counted
---------------
XLA's cost analysis counts one "flop" per *element* of an elementwise op whatever its dtype (a
complex multiply is 1, not 6), so the real-arithmetic work of P1 is counted here by hand from
the formulas the kernel evaluates (``layerstack_jax._kernels.fresnel``, ``_coherent``), per
(angle, wavelength) point of a stack of F films between two media (F + 2 media, F + 1
interfaces), in real floating-point operations (complex multiply 6, complex add 2, complex
divide 11: |w|², z·w̄ and two real divisions, the library's form), a transcendental (complex
√, exp) not counted as ops but timed separately, since one costs tens of FMAs:

====================================  =====================================  ========================
step                                  per point                              real ops
====================================  =====================================  ========================
normal wavevectors (F + 2 media)      n² − s² (cmul + sub), √ in real        (F+2) × (6 + 1 + 2) ops,
                                      arithmetic (Kahan) + branch select     (F+2) csqrt
Fresnel r, t (F + 1 interfaces)       s: 2 cadd, 2 cdiv, 2q; p: 6 cmul,      (F+1) × (28 + 64) ops
                                      2 cadd, 2 cdiv, 2·; (guards: selects)
film phases (F films)                 φ = 2π q d / λ (2 real × complex),     F × (4 + 6) ops, F cexp
                                      e^{iφ} (exp, polynomial cos / sin),
                                      e^{2iφ} (cmul)
Rouard recursion (F steps, s and p)   u = γ e^{2iφ}, D = 1 + r u, γ ← (r +   2F × (6+6+2+2+11+12+11)
                                      u)/D, τ ← t τ e^{iφ}/D                 = 2F × 50 ops
intensities (s and p)                 |γ|², |τ|² × flux ratio (q/n: cdiv)   2 × (3 + 3 + 14) ops
====================================  =====================================  ========================

Ceilings measured on this machine, in the same process (``jax.jit``, float64): the dense
matrix-multiply rate (the FMA peak XLA reaches: 2n³ flops of an n × n product), the rate of a
long elementwise FMA chain on an L2-resident array (the ceiling for fused elementwise code), the
memory bandwidth (a triad on arrays far larger than the caches), and the throughput of the
complex operations the kernel calls — the library's forms (√ in real arithmetic,
``_fresnel._forward_sqrt``; e^{iφ} with polynomial cosine and sine, ``_coherent._phase_factor``;
division as z·w̄/|w|², ``_fresnel.divide``) next to XLA's own ``sqrt``, ``exp`` and ``/``
of complex numbers. The roofline bound is min(peak, intensity × bandwidth); the ratio reported
is achieved / bound.

Bytes moved: XLA's cost analysis counts a ``while`` loop's body once, whatever its trip count,
and the kernel runs its films in a loop, so the traffic is also counted here from the compiled
HLO (:func:`hlo_traffic`): result plus operands of every kernel the program launches, a loop's
body times its trip count. The intensity uses that count.

Where the time goes: the same P1 grid evaluated by micro-kernels that each do one step of the
table above (the library's own functions, same shapes and dtype, each step's result stored),
timed alone; their sum is compared with the library's whole forward, which stores none of them.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import re

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"
_DTYPE_BYTES = {"pred": 1, "s8": 1, "u8": 1, "bf16": 2, "f16": 2, "s16": 2, "u16": 2, "f32": 4, "s32": 4, "u32": 4,
                "f64": 8, "s64": 8, "u64": 8, "c64": 8, "c128": 16}
_NOT_KERNELS = {"parameter", "constant", "get-tuple-element", "tuple", "bitcast", "while", "opt-barrier", "after-all"}


def _best(fn, *args, repeats: int = 7, clock=time.perf_counter) -> float:
    """Least time (s) of ``fn(*args)`` by ``clock`` — wall time by default — over ``repeats``
    calls (already compiled: one warm-up call first)."""
    import jax

    jax.block_until_ready(fn(*args))
    best = np.inf
    for _ in range(repeats):
        t0 = clock()
        jax.block_until_ready(fn(*args))
        best = min(best, clock() - t0)
    return float(best)


def _type_bytes(hlo_type: str) -> int:
    """Bytes of an HLO type (an array ``c128[2,64,1000]{...}`` or a tuple of them)."""
    total = 0
    for dtype, dims in re.findall(r"\b([a-z]+[0-9]*)\[([0-9,]*)\]", hlo_type):
        if dtype in _DTYPE_BYTES:
            total += _DTYPE_BYTES[dtype] * int(np.prod([int(x) for x in dims.split(",") if x] or [1]))
    return total


def _computations(hlo_text: str) -> dict:
    """``{name: [(instruction, type, op, operand names, attributes)]}`` of an HLO module's text."""
    comps, current = {}, None
    for line in hlo_text.splitlines():
        head = re.match(r"^(?:ENTRY )?%([\w.\-]+) .*\{$", line)
        if head:
            current = comps.setdefault("ENTRY" if line.startswith("ENTRY") else head.group(1), [])
            continue
        m = re.match(r"^\s*(?:ROOT )?%([\w.\-]+) = (.*)$", line)
        if current is None or not m:
            continue
        rest = m.group(2)
        if rest.startswith("("):  # tuple type: up to its matching parenthesis
            depth = 0
            for i, ch in enumerate(rest):
                depth += {"(": 1, ")": -1}.get(ch, 0)
                if depth == 0:
                    break
            hlo_type, rest = rest[: i + 1], rest[i + 2:]
        else:
            hlo_type, _, rest = rest.partition(" ")
        op, _, rest = rest.partition("(")
        args, _, attributes = rest.partition(")")
        current.append((m.group(1), hlo_type, op, re.findall(r"%([\w.\-]+)", args), attributes))
    return comps


def hlo_traffic(hlo_text: str) -> float:
    """Bytes read and written by the kernels of a compiled (optimized) HLO module: for every
    instruction of the entry computation that runs as a kernel (fusions, copies, ...; not
    parameters, constants, tuples, bitcasts), its result plus its operands; a ``while`` loop's
    body (recursively) times its known trip count."""
    comps = _computations(hlo_text)

    def traffic(name: str) -> float:
        sizes = {inst: _type_bytes(t) for inst, t, *_ in comps[name]}
        total = 0.0
        for inst, t, op, operands, attributes in comps[name]:
            if op == "while":
                body = re.search(r"body=%([\w.\-]+)", attributes).group(1)
                trips = re.search(r'"known_trip_count":\{"n":"([0-9]+)"', attributes)
                total += traffic(body) * (int(trips.group(1)) if trips else 1)
            elif op not in _NOT_KERNELS:
                total += sizes[inst] + sum(sizes.get(o, 0) for o in operands)
        return total

    return traffic("ENTRY")


def _best_cpu(fn, *args, repeats: int = 7) -> float:
    """Least process CPU time (s, all threads) of ``fn(*args)``: less sensitive than wall time to
    other processes on the machine."""
    return _best(fn, *args, repeats=repeats, clock=time.process_time)


def ops_per_point(films: int) -> dict:
    """Real floating-point operations per (angle, wavelength) point of one stack (module table)."""
    media, interfaces = films + 2, films + 1
    steps = {
        "normal wavevectors": media * (6 + 1 + 2),
        "Fresnel r, t": interfaces * (28 + 64),
        "film phases": films * (4 + 6),
        "Rouard recursion (s, p)": 2 * films * 50,
        "intensities (s, p)": 2 * (3 + 3 + 14),
    }
    transcendentals = {"csqrt": media, "cexp": films}
    return {"steps": steps, "total": sum(steps.values()), "transcendentals": transcendentals}


def ceilings(repeats: int) -> dict:
    """This machine's measured ceilings (float64, jax.jit): see the module docstring."""
    import jax
    import jax.numpy as jnp

    out = {}
    n = 2048
    a = jnp.asarray(np.random.default_rng(0).standard_normal((n, n)))
    mm = jax.jit(lambda x: x @ x)
    out["matmul_gflops"] = 2 * n**3 / _best(mm, a, repeats=repeats) / 1e9

    m, chain = 1 << 15, 256  # 256 KiB: L2-resident; 256 dependent FMAs per element
    x = jnp.linspace(0.0, 1.0, m)

    def fma_chain(v):
        def body(_, w):
            return w * 0.999 + 0.001
        return jax.lax.fori_loop(0, chain, body, v, unroll=16)

    out["elementwise_fma_gflops"] = 2 * chain * m / _best(jax.jit(fma_chain), x, repeats=repeats) / 1e9

    big = 1 << 25  # 256 MiB per array
    b, c = jnp.ones(big), jnp.full(big, 2.0)
    triad = jax.jit(lambda u, v: u + 3.0 * v)
    out["bandwidth_gbs"] = 3 * 8 * big / _best(triad, b, c, repeats=max(3, repeats // 2)) / 1e9
    del b, c
    mid = 1 << 18  # 2 MiB per array: the size of the kernel's (2, 64, 1000) complex arrays (L3)
    b, c = jnp.ones(mid), jnp.full(mid, 2.0)
    out["cache_bandwidth_gbs"] = 3 * 8 * mid / _best(triad, b, c, repeats=repeats * 4) / 1e9

    from layerstack_jax._kernels.coherent import _phase_factor
    from layerstack_jax._kernels.fresnel import _forward_sqrt, divide

    z = jnp.asarray(np.random.default_rng(1).standard_normal(1 << 20) + 1j * np.random.default_rng(2).standard_normal(1 << 20))
    for name, f in (("csqrt", _forward_sqrt), ("cexp", _phase_factor), ("cdiv", lambda w: divide(1.0, w + 2.0)),
                    ("cmul", lambda w: w * (w + 1.0)), ("xla_csqrt", jnp.sqrt), ("xla_cexp", lambda w: jnp.exp(1j * w)),
                    ("xla_cdiv", lambda w: 1.0 / (w + 2.0))):
        out[f"{name}_per_ns"] = z.size / _best(jax.jit(f), z, repeats=repeats) / 1e9
    return out


def micro_kernels(films: int, n_angles: int, n_wl: int, d, n_layers_idx, repeats: int) -> dict:
    """Each step of the kernel alone on P1's grid (module docstring), best wall time in s: the
    library's own functions, each step's result stored (the whole kernel stores none)."""
    import jax
    import jax.numpy as jnp

    from layerstack_jax._kernels.coherent import _film_phase, _phase_factor, _rouard_update
    from layerstack_jax._kernels.fresnel import fresnel_amplitudes, normal_wavevector

    wl = jnp.linspace(400.0, 1000.0, n_wl)
    s = jnp.sin(jnp.linspace(0.0, np.deg2rad(80.0), n_angles))[:, None]  # (A, 1)
    # (F+2, 1, W): one index per wavelength, as the benchmark hands P1 to the library
    n_media = jnp.broadcast_to(jnp.asarray(n_layers_idx, dtype=jnp.complex128)[:, None, None], (films + 2, 1, n_wl))
    d = jnp.asarray(d)[:, None, None]

    wavevectors = jax.jit(normal_wavevector)
    q = wavevectors(n_media, s)  # (F+2, A, W)

    def fresnel(nm, qq):
        return fresnel_amplitudes(nm[:-1], qq[:-1], nm[1:], qq[1:])  # (2, F+1, A, W)

    r, t = jax.jit(fresnel)(n_media, q)

    def phases(qq, dd):
        return _phase_factor(_film_phase(qq[1:-1], dd, wl))

    e1 = jax.jit(phases)(q, d)

    def recursion(rr, tt, ee1):
        gamma, tau = rr[:, -1], tt[:, -1]
        for j in range(films - 1, -1, -1):
            gamma, tau = _rouard_update(gamma, tau, rr[:, j], tt[:, j], ee1[j], ee1[j] * ee1[j])
        return gamma, tau

    gamma, tau = jax.jit(recursion)(r, t, e1)

    def intensities(g, tt, qq):
        flux = jnp.real(qq[-1]) / jnp.real(qq[0])
        return jnp.real(g * jnp.conj(g)), jnp.real(tt * jnp.conj(tt)) * flux

    return {
        "normal wavevectors": _best(wavevectors, n_media, s, repeats=repeats),
        "Fresnel r, t": _best(jax.jit(fresnel), n_media, q, repeats=repeats),
        "film phases": _best(jax.jit(phases), q, d, repeats=repeats),
        "Rouard recursion (s, p)": _best(jax.jit(recursion), r, t, e1, repeats=repeats),
        "intensities (s, p)": _best(jax.jit(intensities), gamma, tau, q, repeats=repeats),
    }


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--out-dir", type=Path, default=RESULTS)
    args = p.parse_args(argv)

    import jax

    jax.config.update("jax_enable_x64", True)
    from . import _ours
    from .cases import P1

    case = P1()
    films, (pols, n_angles, n_wl) = case.n_layers, case.shape
    points = n_angles * n_wl
    built = _ours.build_forward(case)
    compiled = built.fn.lower(*built.args).compile()
    xla = compiled.cost_analysis()
    xla = xla[0] if isinstance(xla, list) else xla
    t_kernel = _best(built.fn, *built.args, repeats=args.repeats)
    cpu_kernel = _best_cpu(built.fn, *built.args, repeats=args.repeats)
    ops = ops_per_point(films)
    peaks = ceilings(args.repeats)
    pieces = micro_kernels(films, n_angles, n_wl, case.d, case.n[:, 0].real, args.repeats)

    total_ops = ops["total"] * points
    achieved = total_ops / t_kernel / 1e9
    bytes_moved = hlo_traffic(compiled.as_text())
    intensity = total_ops / bytes_moved
    bound = min(peaks["elementwise_fma_gflops"], intensity * peaks["bandwidth_gbs"])
    bound_cache = min(peaks["elementwise_fma_gflops"], intensity * peaks["cache_bandwidth_gbs"])
    layer_points = films * points * pols
    transcendental_s = (ops["transcendentals"]["csqrt"] * points / (peaks["csqrt_per_ns"] * 1e9)
                        + ops["transcendentals"]["cexp"] * points / (peaks["cexp_per_ns"] * 1e9))
    result = {
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count(), "jax": jax.__version__,
                    "backend": jax.default_backend(), "load_start": os.getloadavg()},
        "case": case.description, "films": films, "points": points,
        "kernel_s": t_kernel, "kernel_cpu_s": cpu_kernel, "ns_per_layer_point": t_kernel / layer_points * 1e9,
        "ops_per_point": ops, "achieved_gflops": achieved,
        "xla_cost_analysis": {k: float(v) for k, v in xla.items() if k in ("flops", "transcendentals", "bytes accessed")},
        "hlo_traffic_bytes": bytes_moved, "intensity_ops_per_byte": intensity, "ceilings": peaks,
        "roofline_bound_gflops": bound, "roofline_ratio": achieved / bound,
        "roofline_bound_cache_gflops": bound_cache, "roofline_ratio_cache": achieved / bound_cache,
        "of_elementwise_peak": achieved / peaks["elementwise_fma_gflops"], "of_matmul_peak": achieved / peaks["matmul_gflops"],
        "transcendental_time_estimate_s": transcendental_s, "pieces_s": pieces,
        "pieces_sum_s": sum(pieces.values()), "load_end": os.getloadavg(),
    }
    args.out_dir.mkdir(parents=True, exist_ok=True)
    (args.out_dir / "roofline.json").write_text(json.dumps(result, indent=2))
    (args.out_dir / "roofline.md").write_text(_markdown(result))
    print(_markdown(result))
    return result


def _markdown(r: dict) -> str:
    c, o = r["ceilings"], r["ops_per_point"]
    lines = [
        "# Roofline of the coherent kernel (P1)", "",
        f"{r['case']}. jax {r['machine']['jax']} ({r['machine']['backend']}), {r['machine']['cpus']} CPUs, "
        f"load average {r['machine']['load_start'][0]:.2f} at the start, {r['load_end'][0]:.2f} at the end. "
        "Best wall time of the repeats; `python -m benchmarks.roofline`.", "",
        "| quantity | value |", "| --- | --- |",
        f"| P1 forward (public API, jit) | {r['kernel_s'] * 1e3:.1f} ms wall ({r['kernel_cpu_s'] * 1e3:.1f} ms CPU, all threads) "
        f"= {r['ns_per_layer_point']:.2f} ns per layer-point ({r['films']} films × {r['points']} points × 2 polarizations) |",
        f"| real ops per (angle, λ) point (hand count, module docstring) | {o['total']} "
        f"({', '.join(f'{k} {v}' for k, v in o['steps'].items())}); + {o['transcendentals']['csqrt']} complex √, "
        f"{o['transcendentals']['cexp']} complex exp |",
        f"| XLA cost analysis (element ops, complex = 1; a loop body counted once) | {r['xla_cost_analysis'].get('flops', float('nan')):.3g} flops, "
        f"{r['xla_cost_analysis'].get('transcendentals', float('nan')):.3g} transcendentals, "
        f"{r['xla_cost_analysis'].get('bytes accessed', float('nan')) / 1e6:.1f} MB accessed |",
        f"| bytes moved by the compiled program (`hlo_traffic`: every kernel's operands and result, the film loop × its trip count) "
        f"| {r['hlo_traffic_bytes'] / 1e6:.0f} MB |",
        f"| achieved | {r['achieved_gflops']:.2f} GFLOP/s |",
        f"| ceilings: matmul / elementwise FMA chain / bandwidth (DRAM triad) / bandwidth (2 MiB arrays, cache) | "
        f"{c['matmul_gflops']:.1f} GFLOP/s / {c['elementwise_fma_gflops']:.1f} GFLOP/s / {c['bandwidth_gbs']:.1f} GB/s / "
        f"{c['cache_bandwidth_gbs']:.1f} GB/s |",
        f"| complex throughput, the library's forms: √ / e^(iφ) / divide / multiply | {c['csqrt_per_ns']:.3f} / {c['cexp_per_ns']:.3f} / "
        f"{c['cdiv_per_ns']:.3f} / {c['cmul_per_ns']:.3f} per ns |",
        f"| complex throughput, XLA's own `sqrt` / `exp` / `/` | {c['xla_csqrt_per_ns']:.3f} / {c['xla_cexp_per_ns']:.3f} / "
        f"{c['xla_cdiv_per_ns']:.3f} per ns |",
        f"| arithmetic intensity (hand-counted ops / bytes moved) | {r['intensity_ops_per_byte']:.2f} ops/byte (compute-bound side "
        f"when > {c['elementwise_fma_gflops'] / c['bandwidth_gbs']:.2f} for DRAM, "
        f"> {c['elementwise_fma_gflops'] / c['cache_bandwidth_gbs']:.2f} for cache) |",
        f"| roofline bound min(elementwise peak, intensity × bandwidth): DRAM / cache | {r['roofline_bound_gflops']:.1f} / "
        f"{r['roofline_bound_cache_gflops']:.1f} GFLOP/s |",
        f"| **achieved / roofline bound** | **{r['roofline_ratio']:.2f}** against the DRAM bound, "
        f"**{r['roofline_ratio_cache']:.2f}** against the cache bound (of the elementwise peak: {r['of_elementwise_peak']:.2f}, "
        f"of the matmul peak: {r['of_matmul_peak']:.2f}) |",
        f"| transcendentals alone at their measured throughput (library forms) | {r['transcendental_time_estimate_s'] * 1e3:.1f} ms |",
        "", "## Where the time goes (each step alone on the P1 grid, its result stored)", "",
        "| step | time | share of the sum |", "| --- | --- | --- |",
    ]
    total = r["pieces_sum_s"]
    for k, v in r["pieces_s"].items():
        lines.append(f"| {k} | {v * 1e3:.1f} ms | {v / total:.0%} |")
    lines += [f"| sum of the steps | {total * 1e3:.1f} ms | (whole kernel {r['kernel_s'] * 1e3:.1f} ms) |", ""]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
