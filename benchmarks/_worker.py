"""Runs one benchmark (or the peer validation) in its own process; writes a JSON result.

    python -m benchmarks._worker run --bench '{"case": "P1", "impl": "tmm-fast", ...}' --mode full --out r.json
    python -m benchmarks._worker validate --peers tmm-fast,tmm-faster --out v.json

One process per benchmark keeps peak-RSS figures separate, keeps frameworks from
interfering (thread pools, ``jax_enable_x64`` flipped by a peer at import), and contains
crashes. The parent (``python -m benchmarks``) reads the JSON and the child's rusage.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import traceback

import numpy as np

from . import _harness, _ours, _peers
from ._registry import FULL, QUICK, Bench, Mode
from .cases import CoherentStack, get_case, objective


def _impl(name: str):
    if name == _ours.IMPL:
        return _ours
    return _peers.PEERS[name]


def _available(name: str) -> tuple[bool, str]:
    if name == _ours.IMPL:
        fn, desc = _ours.resolve()
        return fn is not None, ("ok" if fn is not None else desc)
    if name not in _peers.PEERS:
        return False, f"missing: unknown implementation {name!r}"
    return _peers.PEERS[name].available()


def _grid_label(stack: CoherentStack, full: CoherentStack) -> str:
    p, a, w = stack.shape
    tag = "full" if stack.shape == full.shape else "subset"
    return f"{tag} {p}x{a}x{w}"


def _agreement(stack: CoherentStack, R: np.ndarray, T: np.ndarray, grid: tuple[int, int]) -> dict:
    sub = stack.strided_subset(*grid)
    a_idx = np.asarray(sub.meta["angle_idx"])
    w_idx = np.asarray(sub.meta["wl_idx"])
    R0, T0 = _peers.reference(sub)
    Rs = R[:, a_idx][:, :, w_idx]
    Ts = T[:, a_idx][:, :, w_idx]
    return {
        "max_abs_dR": float(np.max(np.abs(Rs - R0))),
        "max_abs_dT": float(np.max(np.abs(Ts - T0))),
        "agreement_points": int(R0.size),
    }


GRAD_RTOL = 1e-8


def _grad_check(impl, case: CoherentStack, grid: tuple[int, int], h: float = 1e-2) -> dict:
    """Gradient of mean(R) w.r.t. d on a small sub-grid: implementation vs tmm finite differences.

    Fourth-order central stencil, h = 0.01 nm: truncation and rounding both ~1e-11 relative
    on P1 (second-order differences would be limited to ~1e-7 by truncation at h = 1e-3 nm).
    """
    small = case.strided_subset(*grid)
    b = impl.build_value_and_grad(small)
    value, grad = b.to_numpy(_harness.block(b.fn(*b.args)))

    def f(d):
        s = CoherentStack(small.name, small.n, np.asarray(d, float), small.wavelengths, small.angles, small.pols)
        return objective(_peers.reference(s)[0])

    d0 = small.d.astype(float)
    g_fd = np.empty_like(d0)
    for i in range(d0.size):
        e = np.zeros_like(d0)
        e[i] = h
        g_fd[i] = (-f(d0 + 2 * e) + 8 * f(d0 + e) - 8 * f(d0 - e) + f(d0 - 2 * e)) / (12 * h)
    v0 = f(d0)
    scale = float(np.max(np.abs(g_fd)))
    return {
        "grad_check_points": int(small.n_points),
        "grad_check_h_nm": h,
        "value_abs_err": float(abs(value - v0)),
        "grad_max_abs_err": float(np.max(np.abs(np.asarray(grad) - g_fd))),
        "grad_max_rel_err": float(np.max(np.abs(np.asarray(grad) - g_fd)) / scale) if scale > 0 else None,
    }


def run_bench(bench: Bench, mode: Mode, tmm_full_grid: bool = False) -> dict:
    case = get_case(bench.case)
    grid = bench.quick_grid if mode.name == "quick" else bench.grid
    if bench.impl == "tmm" and tmm_full_grid:
        grid = None
    stack = case if grid is None else case.strided_subset(*grid)
    row: dict = {
        "case": bench.case,
        "impl": bench.impl,
        "kind": bench.kind,
        "grid": _grid_label(stack, case),
        "points_timed": stack.n_points,
        "points_full": case.n_points,
        "status": None,
        "notes": [bench.note] if bench.note else [],
    }
    ok, why = _available(bench.impl)
    if not ok:
        row["status"] = why
        return row
    impl = _impl(bench.impl)
    if bench.kind == "forward":
        built = impl.build_forward(stack)
    elif bench.kind == "value_and_grad":
        built = impl.build_value_and_grad(stack)
    else:
        raise ValueError(f"unknown kind {bench.kind!r}")
    row["notes"] += built.notes
    row["rss_after_setup_bytes"] = _harness.peak_rss_bytes()
    with _harness.CpuContention() as contention:
        timing, out = _harness.measure(
            built.fn, *built.args, warmup=mode.warmup, repeats=mode.repeats, min_time=mode.min_time,
            max_time=mode.max_time, return_output=True,
        )
    row["peak_rss_bytes"] = _harness.peak_rss_bytes()
    row["foreign_cpu_frac"] = contention.foreign_frac
    row["steal_cpu_frac"] = contention.steal_frac
    if contention.foreign_frac is not None and contention.foreign_frac > 0.1:
        row["notes"].append(f"other processes used {100 * contention.foreign_frac:.0f}% of the CPUs while timing")
    row["timing"] = timing.as_dict()
    row.update(
        first_call_s=timing.first_call_s,
        # ahead-of-time: trace + lower + XLA compile (split kept in row["timing"])
        compile_s=(timing.compile_s or 0.0) + (timing.lower_s or 0.0) if timing.compile_method == "aot" else timing.compile_s,
        compile_method=timing.compile_method,
        min_s=timing.min_s,
        median_s=timing.median_s,
        per_point_s=timing.median_s / stack.n_points,
    )
    row["full_grid_extrapolated"] = stack.shape != case.shape
    row["full_grid_s"] = row["per_point_s"] * case.n_points
    if row["full_grid_extrapolated"]:
        row["notes"].append(
            f"timed on {stack.n_points} of {case.n_points} points; full-grid time extrapolated from per-point cost"
        )

    status = "ok"
    if bench.kind == "forward":
        R, T = built.to_numpy(out)
        if R.shape != stack.shape or T.shape != stack.shape:
            return dict(row, status=f"failed: output shape {R.shape}/{T.shape}, expected {stack.shape}")
        if not (np.all(np.isfinite(R)) and np.all(np.isfinite(T))):
            status = "failed: non-finite R or T"
        lossless = bool(np.all(stack.n.imag == 0))
        if lossless:
            row["max_abs_energy_err"] = float(np.max(np.abs(R + T - 1.0)))
        if bench.impl != "tmm":
            row.update(_agreement(stack, R, T, mode.agreement_grid))
            err = max(row["max_abs_dR"], row["max_abs_dT"])
            if not err <= _peers.VALIDATION_TOL and status == "ok":
                status = f"failed: max abs error vs tmm {err:.1e} > {_peers.VALIDATION_TOL:g}"
        else:
            row["notes"].append("reference implementation")
    else:
        value, grad = built.to_numpy(out)
        row["value"] = float(value)
        row["grad"] = np.asarray(grad, dtype=float).tolist()
        if not (np.isfinite(value) and np.all(np.isfinite(grad))):
            status = "failed: non-finite value or gradient"
        if mode.grad_check_grid is not None:
            gc = _grad_check(impl, case, mode.grad_check_grid)
            row.update(gc)
            row["notes"].append(
                f"gradient vs tmm 4th-order central differences (h={gc['grad_check_h_nm']} nm) on a "
                f"{gc['grad_check_points']}-point sub-grid: max rel err {gc['grad_max_rel_err']:.1e}, "
                f"|value err| {gc['value_abs_err']:.1e}"
            )
            if not (gc["grad_max_rel_err"] is not None and gc["grad_max_rel_err"] < GRAD_RTOL) and status == "ok":
                status = f"failed: gradient disagrees with tmm finite differences (rel err {gc['grad_max_rel_err']})"
        else:
            row["notes"].append("gradient not checked (quick mode)")
    row["status"] = status
    return row


def validate_peers(names: list[str]) -> dict:
    res = {}
    for name in names:
        p = _peers.PEERS[name]
        t0 = time.perf_counter()
        ok, why = p.available()
        if not ok:
            res[name] = {"version": p.version(), "status": why, "description": p.description}
            continue
        try:
            v = _peers.validate(name)
            res[name] = {
                "version": v.version,
                "status": v.status,
                "max_abs_dR": v.max_abs_dR,
                "max_abs_dT": v.max_abs_dT,
                "validation_stack": v.stack,
                "description": p.description,
            }
        except Exception as e:
            res[name] = {"version": p.version(), "status": f"failed: {type(e).__name__}: {e}", "description": p.description}
        res[name]["validation_s"] = time.perf_counter() - t0
    return res


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks._worker")
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("--bench", required=True, help="JSON of a Bench")
    r.add_argument("--mode", choices=["quick", "full"], default="full")
    r.add_argument("--tmm-full-grid", action="store_true")
    r.add_argument("--out", required=True)
    v = sub.add_parser("validate")
    v.add_argument("--peers", required=True)
    v.add_argument("--out", required=True)
    a = ap.parse_args(argv)

    t0 = time.perf_counter()
    try:
        if a.cmd == "run":
            spec = json.loads(a.bench)
            for k in ("grid", "quick_grid"):
                if spec.get(k) is not None:
                    spec[k] = tuple(spec[k])
            payload = run_bench(Bench(**spec), QUICK if a.mode == "quick" else FULL, a.tmm_full_grid)
        else:
            payload = validate_peers([p for p in a.peers.split(",") if p])
        rc = 0
    except Exception as e:
        payload = {"status": f"failed: {type(e).__name__}: {e}", "error": traceback.format_exc()}
        rc = 0  # the failure is reported in the payload
    payload = dict(payload, worker_wall_s=time.perf_counter() - t0)
    _harness.write_json(payload, a.out)
    return rc


if __name__ == "__main__":
    sys.exit(main())
