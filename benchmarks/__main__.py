"""``python -m benchmarks [--quick] [--only P1,P2,P3,MEMORY,...] [--impl tmm-fast,...]``

Runs the registered P1 benchmarks (peers and layerstack_jax), then the whole-model sections
(P2, P3, MEMORY, SCALING, ACCURACY, PRECISION; ``benchmarks._sections``), each in its own
subprocess, and writes ``benchmarks/results/latest.md`` and ``latest.json`` (plus the PNG
plots next to them). Nothing is installed: a peer that is not importable is reported as missing.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import sys
import tempfile
import time
from pathlib import Path

from . import _harness, _sections
from ._registry import FULL, QUICK, build_registry
from .cases import CASES, get_case
from .targets import targets

REPO_ROOT = Path(__file__).resolve().parent.parent


def _split(s: str | None) -> list[str] | None:
    return None if not s else [x.strip() for x in s.split(",") if x.strip()]


def _worker(args: list[str], timeout: float) -> tuple[dict | None, _harness.SubprocessResult]:
    with tempfile.TemporaryDirectory(prefix="layerstack-bench-") as td:
        out = Path(td) / "out.json"
        res = _harness.run_subprocess(
            [sys.executable, "-m", "benchmarks._worker", *args, "--out", str(out)],
            cwd=REPO_ROOT, timeout=timeout, env=dict(os.environ),
        )
        payload = json.loads(out.read_text()) if out.exists() else None
    return payload, res


def _fail_reason(res: _harness.SubprocessResult) -> str:
    if res.timed_out:
        return f"failed: worker timed out after {res.wall_s:.0f} s"
    tail = [ln for ln in res.stderr.strip().splitlines() if ln.strip()][-1:] or ["(no stderr)"]
    return f"failed: worker exited with code {res.returncode}: {tail[0][:300]}"


def _run_section(name: str, quick: bool, out_dir: Path) -> dict:
    timeout = _sections.TIMEOUTS[name]  # same in quick mode: the shared machine compiles slowly
    with tempfile.TemporaryDirectory(prefix="layerstack-section-") as td:
        out = Path(td) / "out.json"
        argv = [sys.executable, "-m", "benchmarks._sections", name, "--out", str(out), "--plot-dir", str(out_dir)]
        if quick:
            argv.append("--quick")
        res = _harness.run_subprocess(argv, cwd=REPO_ROOT, timeout=timeout, env=dict(os.environ))
        payload = json.loads(out.read_text()) if out.exists() else {"status": _fail_reason(res)}
    payload["process_wall_s"] = res.wall_s
    payload["loadavg_after"] = _harness.loadavg()
    return payload


def _write(out_dir, command, mode, machine, benches, peers, reg, rows, section_results, t_start, partial=False):
    """Write latest.md / latest.json (also after each section, so a cut-short run leaves a report)."""
    case_info = []
    for name in sorted({b.case for b in benches}):
        c = get_case(name)
        case_info.append({"name": name, "description": c.description, "n_points": c.n_points, "shape": c.shape,
                          "n_layers": c.n_layers, "d_nm": c.d.tolist()})
    payload = {
        "command": command + (" (PARTIAL: run still in progress or cut short)" if partial else ""),
        "mode": mode.name,
        "mode_settings": mode.__dict__,
        "machine": machine,
        "cases": case_info,
        "peers": peers,
        "hooks": reg.hooks,
        "rows": rows,
        "sections": section_results,
    }
    payload["targets"] = targets(payload)
    payload["total_wall_s"] = time.perf_counter() - t_start
    jp = _harness.write_json(payload, Path(out_dir) / "latest.json")
    mp = _harness.write_markdown(payload, Path(out_dir) / "latest.md",
                                 _sections.markdown_lines(payload.get("sections", {})))
    return mp, jp


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="reduced grids, 1 repeat, no gradient check (< 60 s)")
    ap.add_argument("--only", help=f"comma-separated cases/sections (known: {', '.join([*CASES, *_sections.SECTIONS])})")
    ap.add_argument("--impl", help="comma-separated implementations to run (default: all registered)")
    ap.add_argument("--tmm-full-grid", action="store_true", help="time tmm on the full grid instead of a subset (slow)")
    ap.add_argument("--no-validate", action="store_true", help="skip validating peers against tmm on a random stack")
    ap.add_argument("--out-dir", default=str(_harness.RESULTS_DIR), help="where latest.md / latest.json go")
    ap.add_argument("--list", action="store_true", help="list registered benchmarks and exit")
    a = ap.parse_args(argv)

    mode = QUICK if a.quick else FULL
    reg = build_registry()
    cases = _split(a.only)
    impls = _split(a.impl)
    for c in cases or []:
        if c not in CASES and c not in _sections.SECTIONS:
            ap.error(f"unknown case {c!r}; known: {', '.join([*CASES, *_sections.SECTIONS])}")
    benches = [b for b in reg.benches if (cases is None or b.case in cases) and (impls is None or b.impl in impls)
               and (b.in_quick or not a.quick)]
    sections = [s for s in _sections.SECTIONS if (cases is None or s in cases) and impls in (None, ["layerstack_jax"])]
    if a.list:
        for b in reg.benches:
            print(f"{b.key:40s} grid={b.grid or 'full'} quick_grid={b.quick_grid if b.in_quick else '(not in --quick)'}")
        for k, v in reg.hooks.items():
            print(f"hook {k}: {v}")
        for k, v in _sections.SECTIONS.items():
            print(f"section {k:12s} {v}")
        return 0

    t_start = time.perf_counter()
    command = "python -m benchmarks " + " ".join(shlex.quote(x) for x in (argv if argv is not None else sys.argv[1:]))
    print(f"[benchmarks] mode={mode.name}, {len(benches)} benchmark(s), sections: {', '.join(sections) or 'none'}", flush=True)
    machine = _harness.machine_info(dtype="float64")
    warn = _harness.busy_warning(machine.get("loadavg_at_start"), machine.get("cpu_count") or 1)
    if warn:
        print(f"[benchmarks] WARNING: {warn}", flush=True)

    from ._peers import PEERS  # light: imports no peer

    # 1. validate peers against tmm (one subprocess; a crashing peer cannot take the runner down)
    peers: dict[str, dict] = {}
    if benches and not a.no_validate and mode.validate_peers:
        names = [p for p in PEERS if impls is None or p in impls or p == "tmm"]
        payload, res = _worker(["validate", "--peers", ",".join(names)], timeout=mode.timeout)
        if payload is None or isinstance(payload.get("status"), str):  # worker-level failure
            reason = (payload or {}).get("status") or _fail_reason(res)
            peers = {n: {"version": PEERS[n].version(), "status": f"failed: validation worker: {reason}"} for n in names}
        else:
            payload.pop("worker_wall_s", None)
            peers = payload
        for n, st in peers.items():
            print(f"[benchmarks] peer {n:14s} {st.get('version') or '-':8s} {st['status']}", flush=True)

    # 2. run each benchmark in its own process
    rows = []
    for b in benches:
        pst = peers.get(b.impl)
        if pst is not None and not pst["status"].startswith("ok"):
            rows.append({"case": b.case, "impl": b.impl, "kind": b.kind, "status": pst["status"],
                         "notes": ["not timed: peer is missing or failed validation"]})
            print(f"[benchmarks] {b.key:36s} skipped: {pst['status']}", flush=True)
            continue
        args = ["run", "--bench", json.dumps(b.as_dict()), "--mode", mode.name]
        if a.tmm_full_grid:
            args.append("--tmm-full-grid")
        t0 = time.perf_counter()
        load_before = _harness.loadavg()
        payload, res = _worker(args, timeout=mode.timeout)
        row = {"case": b.case, "impl": b.impl, "kind": b.kind, "loadavg_before": load_before}
        if payload is None:
            row["status"] = _fail_reason(res)
        else:
            row.update(payload)
            if row.get("error"):
                print(row["error"], file=sys.stderr)
        row["process_peak_rss_bytes"] = res.peak_rss_bytes
        row["process_wall_s"] = res.wall_s
        rows.append(row)
        med = row.get("median_s")
        print(f"[benchmarks] {b.key:36s} {row['status']}"
              + (f"  median {med * 1e3:.3g} ms, first call {row['first_call_s']:.3g} s" if med is not None else "")
              + f"  ({time.perf_counter() - t0:.1f} s)", flush=True)

    # 3. whole-model sections, each in its own process (its own peak RSS, its own x64 setting)
    out_dir = Path(a.out_dir)
    section_results: dict[str, dict] = {}
    for name in sections:
        t0 = time.perf_counter()
        res = _run_section(name, a.quick, out_dir)
        section_results[name] = res
        _write(out_dir, command, mode, machine, benches, peers, reg, rows, section_results, t_start, partial=True)
        print(f"[benchmarks] section {name:10s} {res.get('status')}  ({time.perf_counter() - t0:.1f} s)", flush=True)
        if res.get("error"):
            print(res["error"], file=sys.stderr)

    mp, jp = _write(out_dir, command, mode, machine, benches, peers, reg, rows, section_results, t_start)
    print(f"[benchmarks] wrote {mp} and {jp} in {time.perf_counter() - t_start:.1f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
