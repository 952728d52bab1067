"""The project's performance targets (issue 5), judged on a benchmark payload.

Each target gives ``{"target", "measured", "met"}``; ``met`` is None where the figure is missing
(case not run or failed). Timings are judged on the minimum over repeats (the least contended
estimate on a shared machine); the median is shown next to it.
"""

from __future__ import annotations

TARGET_P1_FORWARD_S = 0.3
TARGET_P1_GRAD_S = 1.0
TARGET_P2_SPECTRA_PER_S = 1000.0
TARGET_GRAD_RATIO = 3.0
TARGET_COMPILE_S = 5.0


def _row(payload: dict, impl: str, kind: str, case: str = "P1") -> dict | None:
    for r in payload.get("rows", []):
        if r.get("case") == case and r.get("impl") == impl and r.get("kind") == kind and r.get("min_s") is not None:
            return r
    return None


def _t(name: str, target: str, measured: str | None, met: bool | None) -> dict:
    return {"name": name, "target": target, "measured": measured or "not measured", "met": met}


def targets(payload: dict) -> list[dict]:
    out = []
    sec = payload.get("sections", {})
    f = _row(payload, "layerstack_jax", "forward")
    g = _row(payload, "layerstack_jax", "value_and_grad")
    tf = _row(payload, "tmm-fast", "forward")
    if f:
        out.append(_t("P1 forward", f"≤ {TARGET_P1_FORWARD_S} s", f"{f['min_s']:.3f} s (median {f['median_s']:.3f})",
                      f["min_s"] <= TARGET_P1_FORWARD_S))
        out.append(_t("P1 forward faster than tmm-fast", "< tmm-fast",
                      f"{f['min_s']:.3f} s vs {tf['min_s']:.3f} s" if tf else None,
                      (f["min_s"] < tf["min_s"]) if tf else None))
    else:
        out.append(_t("P1 forward", f"≤ {TARGET_P1_FORWARD_S} s", None, None))
    if g:
        out.append(_t("P1 value-and-gradient", f"≤ {TARGET_P1_GRAD_S} s", f"{g['min_s']:.3f} s (median {g['median_s']:.3f})",
                      g["min_s"] <= TARGET_P1_GRAD_S))
        if f:
            ratio = g["min_s"] / f["min_s"]
            out.append(_t("P1 gradient / forward", f"≤ {TARGET_GRAD_RATIO}", f"{ratio:.2f}", ratio <= TARGET_GRAD_RATIO))
    for name, r in (("P1 forward", f), ("P1 value-and-gradient", g)):
        if r and r.get("compile_s") is not None:
            out.append(_t(f"compile: {name}", f"≤ {TARGET_COMPILE_S} s", f"{r['compile_s']:.2f} s",
                          r["compile_s"] <= TARGET_COMPILE_S))
    p2 = sec.get("P2", {})
    if "forward" in p2:
        sp = p2["forward"]["spectra_per_s"]
        out.append(_t("P2 forward throughput", f"≥ {TARGET_P2_SPECTRA_PER_S:.0f} spectra/s", f"{sp:.0f} spectra/s",
                      sp >= TARGET_P2_SPECTRA_PER_S))
        for key, label in (("value_and_grad", "P2 value+gradient (reverse) / forward"),
                           ("grad_jacfwd", "P2 gradient (jacfwd) / forward"),
                           ("jacobian", "P2 Jacobian 401×3 (jacfwd) / forward")):
            if key in p2:
                r = p2[key]["ratio_to_forward"]
                out.append(_t(label, f"≤ {TARGET_GRAD_RATIO}", f"{r:.2f}", r <= TARGET_GRAD_RATIO))
        c = p2["forward"]["compile_s"]
        out.append(_t("compile: P2 forward", f"≤ {TARGET_COMPILE_S} s", f"{c:.2f} s", c <= TARGET_COMPILE_S))
    else:
        out.append(_t("P2 forward throughput", f"≥ {TARGET_P2_SPECTRA_PER_S:.0f} spectra/s", None, None))
    p3 = sec.get("P3", {})
    if "forward" in p3:
        for key, label in (("value_and_grad", "P3 value+gradient (reverse) / forward"),
                           ("jacfwd", "P3 Jacobian 401×3 (jacfwd) / forward")):
            r = p3[key]["ratio_to_forward"]
            out.append(_t(label, f"≤ {TARGET_GRAD_RATIO}", f"{r:.2f}", r <= TARGET_GRAD_RATIO))
        c = p3["forward"]["compile_s"]
        out.append(_t("compile: P3 forward", f"≤ {TARGET_COMPILE_S} s", f"{c:.2f} s", c <= TARGET_COMPILE_S))
    mem = sec.get("MEMORY", {})
    h = mem.get("headline")
    if h:
        ok = h.get("status") == "ok"
        out.append(_t(f"bounded memory, {h['n']:,} spectra in chunks", "< 2 GiB peak RSS",
                      f"{h['peak_rss_bytes'] / 2**20:.0f} MiB at chunk {h['chunk']}" if ok else h.get("status"),
                      (h["peak_rss_bytes"] < 2 * 2**30) if ok else None))
    return out


def markdown(rows: list[dict]) -> list[str]:
    lines = ["| target | goal | measured | met? |", "|---|---|---|---|"]
    for r in rows:
        met = "—" if r["met"] is None else ("yes" if r["met"] else "**NO**")
        lines.append(f"| {r['name']} | {r['target']} | {r['measured']} | {met} |")
    return lines
