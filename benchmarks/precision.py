"""PRECISION: float32 against float64 on CPU, P1 and P2 — speed and maximum error.

    python -m benchmarks._sections PRECISION --out prec.json [--quick]

``jax_enable_x64`` is process-wide, so each precision runs in its own process
(``python -m benchmarks.precision --child --dtype float32|float64 --dir D``), which writes its
timings (JSON) and outputs (``.npz``); the parent compares them.

* P1: ``benchmarks.cases.P1`` (128 000 points) through ``_ours.coherent_rt`` (the public
  ``layerstack_jax.specular``), jitted; inputs complex64/float32 in the float32 process.
  Errors: max |ΔR|, |ΔT| of float32 against float64, and of both against ``tmm.coh_tmm`` on an
  evenly spread 16 × 100 (angles × wavelengths) sub-grid.
* P2: :func:`benchmarks.radiometric.build` (3 incoherent layers over a Lambertian background,
  401 λ, sphere SCE), a batch of samples with ``lax.map`` over blocks of 4. Errors: max |ΔR| of
  float32 against float64 over the batch, and of both against the independent reference
  (tests/reference.py: numpy Beer recursion + scipy quad, eq. 78) on a few wavelengths of
  sample 0.

No GPU is lent to this task: GPU figures are not measured.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

from . import _harness

P2_BATCH = {"full": 400, "quick": 8}
P2_BLOCK = 4
P2_REF_WL = (380.0, 480.0, 580.0, 680.0, 780.0)


def child(dtype: str, out_dir: Path, quick: bool) -> None:
    from ._sections import setup_jax, timed

    x64 = dtype == "float64"
    jax = setup_jax(x64)
    import jax.numpy as jnp

    import layerstack_jax as ls

    from . import _ours
    from .cases import P1
    from .radiometric import build

    fdt, cdt = (jnp.float64, jnp.complex128) if x64 else (jnp.float32, jnp.complex64)
    case = P1()
    if quick:
        case = case.strided_subset(8, 100)
    args = (jnp.asarray(case.n, cdt), jnp.asarray(case.d, fdt), jnp.asarray(case.wavelengths, fdt),
            jnp.asarray(case.angles, fdt))
    fn = jax.jit(_ours.coherent_rt)
    t1, (R, T) = timed(fn, *args, quick=quick)
    res = {"dtype": dtype, "P1": dict(t1, points=case.n_points, out_dtype=str(R.dtype))}

    model, wl, *_ = build(ls.DEFAULT_NODES, fdt)
    batch = P2_BATCH["quick" if quick else "full"]
    H = jnp.asarray(np.random.default_rng(0).uniform(2e3, 3e4, (batch, 3)), fdt)
    f2 = jax.jit(lambda H: jax.lax.map(model, H, batch_size=P2_BLOCK))
    t2, R2 = timed(f2, H, quick=quick)
    res["P2"] = dict(t2, batch=batch, spectra_per_s=batch / t2["min_s"], out_dtype=str(R2.dtype))
    np.savez(out_dir / f"{dtype}.npz", R1=np.asarray(R, np.float64), T1=np.asarray(T, np.float64),
             R2=np.asarray(R2, np.float64), wl=np.asarray(wl, np.float64), H=np.asarray(H, np.float64))
    (out_dir / f"{dtype}.json").write_text(json.dumps(res))


def _p2_reference(h, wl_nm: float) -> float:
    """Sphere SCE reflectance of the P2 stack at one wavelength (tests/reference.py, eq. 78)."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    import reference as ref

    i = int(round(wl_nm - 380.0))  # 401 λ, 1 nm steps from 380
    wl = np.linspace(380.0, 780.0, 401)
    alpha = [2e-5 * (1.0 + np.sin(wl / 50.0 + j)) for j in range(3)]  # as radiometric.build
    rho = 0.3 + 0.5 * np.exp(-(((wl - 550.0) / 80.0) ** 2))
    n_list = [1.0, 1.5, 1.6, 1.45, 1.52]
    ah = [float(alpha[j][i]) * h[j] for j in range(3)]
    T = ref.beer_stack_R_T("u", n_list, ah, np.deg2rad(8.0))[1]
    r_b, t_b = ref.diffuse_beer_stack(n_list, ah, side="back")
    return t_b * rho[i] * T / (1 - rho[i] * r_b)


def run(quick: bool = False, out_dir=None) -> dict:
    from .cases import P1
    from ._peers import reference as tmm_reference

    res: dict = {}
    with tempfile.TemporaryDirectory(prefix="layerstack-prec-") as td:
        d = Path(td)
        for dtype in ("float64", "float32"):
            argv = [sys.executable, "-m", "benchmarks.precision", "--child", "--dtype", dtype, "--dir", td]
            if quick:
                argv.append("--quick")
            p = _harness.run_subprocess(argv, cwd=Path(__file__).resolve().parent.parent, env=dict(os.environ),
                                        timeout=600)
            if p.returncode != 0 or not (d / f"{dtype}.json").exists():
                tail = (p.stderr.strip().splitlines() or ["(no stderr)"])[-1]
                raise RuntimeError(f"{dtype} child failed: {tail}")
            res[dtype] = json.loads((d / f"{dtype}.json").read_text())
            res[dtype]["peak_rss_bytes"] = p.peak_rss_bytes
        a64, a32 = np.load(d / "float64.npz"), np.load(d / "float32.npz")
        case = P1()
        if quick:
            case = case.strided_subset(8, 100)
        sub = case.strided_subset(8 if quick else 16, 25 if quick else 100)
        ai, wi = np.asarray(sub.meta["angle_idx"]), np.asarray(sub.meta["wl_idx"])
        R0, T0 = tmm_reference(sub)
        err = {"P1": {}, "P2": {}}
        err["P1"]["f32_vs_f64"] = float(max(np.max(np.abs(a32["R1"] - a64["R1"])), np.max(np.abs(a32["T1"] - a64["T1"]))))
        for dt, a in (("float64", a64), ("float32", a32)):
            Rs, Ts = a["R1"][:, ai][:, :, wi], a["T1"][:, ai][:, :, wi]
            err["P1"][f"{dt}_vs_tmm"] = float(max(np.max(np.abs(Rs - R0)), np.max(np.abs(Ts - T0))))
        err["P1"]["tmm_points"] = int(R0.size)
        err["P2"]["f32_vs_f64"] = float(np.max(np.abs(a32["R2"] - a64["R2"])))
        wls = P2_REF_WL[:2] if quick else P2_REF_WL
        h0 = a64["H"][0]
        ref = np.array([_p2_reference(h0, w) for w in wls])
        idx = [int(round(w - 380.0)) for w in wls]
        for dt, a in (("float64", a64), ("float32", a32)):
            err["P2"][f"{dt}_vs_reference"] = float(np.max(np.abs(a["R2"][0, idx] - ref)))
        err["P2"]["reference_points"] = len(wls)
    res["errors"] = err
    res["gpu"] = "not measured: no GPU machine is lent to this task"
    return res


def markdown(r: dict) -> list[str]:
    e = r["errors"]
    lines = ["CPU only — **GPU figures are not measured** (no GPU machine was lent to this task). "
             "min wall time per call, same inputs rounded to the dtype; CPU s/call = process CPU time per call.", "",
             "| case | dtype | min (ms) | median (ms) | CPU s / call | compile (s) | max abs err vs float64 | "
             "max abs err vs independent reference | foreign CPU |",
             "|---|---|---|---|---|---|---|---|---|"]
    for case, ref_key, ref_name in (("P1", "vs_tmm", f"tmm ({e['P1']['tmm_points']} pts)"),
                                    ("P2", "vs_reference", f"scipy/Beer ref ({e['P2']['reference_points']} λ)")):
        for dt in ("float64", "float32"):
            t = r[dt][case]
            vs64 = "—" if dt == "float64" else f"{e[case]['f32_vs_f64']:.1e}"
            extra = f" ({t['spectra_per_s']:.0f} spectra/s)" if case == "P2" else ""
            lines.append(f"| {case} | {dt} | {t['min_s'] * 1e3:.3g}{extra} | {t['median_s'] * 1e3:.3g} | {t['cpu_s_per_call']:.3g} | "
                         f"{t['compile_s']:.2f} | {vs64} | {e[case][f'{dt}_{ref_key}']:.1e} vs {ref_name} | "
                         f"{100 * (t['foreign_cpu_frac'] or 0):.0f}% |")
    s1 = r["float64"]["P1"]["min_s"] / r["float32"]["P1"]["min_s"]
    s2 = r["float64"]["P2"]["min_s"] / r["float32"]["P2"]["min_s"]
    lines += ["", f"float32 speed-up on CPU (min wall): P1 × {s1:.2f}, P2 × {s2:.2f}."]
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.precision")
    ap.add_argument("--child", action="store_true")
    ap.add_argument("--dtype", choices=["float32", "float64"], default="float64")
    ap.add_argument("--dir", required=True)
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args(argv)
    child(a.dtype, Path(a.dir), a.quick)
    return 0


if __name__ == "__main__":
    sys.exit(main())
