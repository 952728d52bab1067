r"""A design file run: :func:`run_design` optimises what :func:`~fitting.load_design` read
(format: :mod:`fitting._design_file`) with :mod:`fitting._design` and evaluates every target on
the result (:class:`DesignOutcome`); :func:`design_report` says it in words,
:func:`design_stack_dict` gives the designed stack as a stack-file dict and :func:`plot_design`
draws it.
"""

from __future__ import annotations

import dataclasses
import os
import time
from pathlib import Path
from typing import Mapping, Optional

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import layerstack_jax as ls
from layerstack_jax import LayerstackError

from ._design import (
    DesignResult,
    YieldResult,
    optimize_thicknesses,
    thickness_yield,
    with_thicknesses,
)
from ._design_file import QUANTITY, DesignFile, DesignTarget
from ._design_targets import SpectralTarget, merit
from ._needle import needle_design

__all__ = ["TargetOutcome", "DesignOutcome", "run_design", "design_report", "design_stack_dict", "plot_design"]


# ------------------------------------------------------------------------------- running
@dataclasses.dataclass(frozen=True)
class TargetOutcome:
    """A target evaluated on the design: ``values`` ``(A, W)`` (spectral) or Lab ``(A, 3)``,
    ``delta_e`` ``(A,)`` for colour targets, ``met`` the pass criterion."""

    target: DesignTarget
    values: np.ndarray
    delta_e: Optional[np.ndarray]
    merit: float
    met: bool


@dataclasses.dataclass(frozen=True)
class DesignOutcome:
    """Everything :func:`run_design` found (see :func:`design_report`)."""

    design: DesignFile
    stack: ls.Stack  # designed, layers named by layer_specs keys
    initial_merit: float
    merit: float
    result: DesignResult  # of the last optimisation
    history: list  # needle steps (empty without needle)
    targets: tuple  # TargetOutcome per target
    yield_: Optional[YieldResult]
    seconds: float

    @property
    def met(self) -> bool:
        """Every target within spec, and the yield reaches ``min_yield`` when one is required."""
        ok = all(t.met for t in self.targets)
        if self.design.min_yield is not None and self.yield_ is not None:
            ok = ok and self.yield_.fraction >= self.design.min_yield
        return ok


def _merge_adjacent(stack: ls.Stack) -> ls.Stack:
    """Adjacent coherent layers of the same material (a host split by a needle that then
    vanished) become one layer of their summed thickness — optically the same stack."""
    layers: list = []
    for layer in stack.layers:
        if layers and layer.coherent and layers[-1].coherent and layer.name == layers[-1].name:
            total = float(np.asarray(layers[-1].thickness)) + float(np.asarray(layer.thickness))
            layers[-1] = eqx.tree_at(lambda lay: lay.thickness, layers[-1], total)
        else:
            layers.append(eqx.tree_at(lambda lay: lay.thickness, layer, float(np.asarray(layer.thickness))))
    return ls.Stack(stack.ambient, layers, stack.exit)


def _of_thicknesses(stack: ls.Stack, fn):
    """``fn(stack)`` compiled once as a function of the layer thicknesses (materials stay
    constants): applies to every stack of the same layout. Op-by-op evaluation would compile
    hundreds of small kernels instead."""
    every = tuple(range(len(stack.layers)))
    compiled = jax.jit(lambda d: fn(with_thicknesses(stack, every, d)))
    return lambda st: compiled(jnp.asarray([float(np.asarray(layer.thickness)) for layer in st.layers]))


def _summary(targets: tuple):
    """stack → (total merit, per target: values, ΔE2000 or None, merit, within spec)."""
    def summary(stack):
        rows = []
        for t in targets:
            values = t.parts[0].evaluate(stack)
            delta_e = ls.delta_e_2000(values, t.parts[0].lab) if t.is_colour else None
            ok = jnp.all(jnp.stack([c.within_spec(stack) for c in t.checks]))
            rows.append((values, delta_e, sum(p.merit(stack) for p in t.parts), ok))
        return merit(stack, [p for t in targets for p in t.parts]), rows

    return summary


def _outcomes(targets: tuple, rows) -> tuple:
    return tuple(
        TargetOutcome(t, np.asarray(values, float), None if delta_e is None else np.asarray(delta_e, float).reshape(-1),
                      float(m), bool(ok))
        for t, (values, delta_e, m, ok) in zip(targets, rows)
    )


def run_design(design: DesignFile) -> DesignOutcome:
    """Optimise the free thicknesses of ``design`` (multi-start L-BFGS-B), then grow it with
    needles and refine it for thickness errors when asked; evaluate targets and yield."""
    start_time = time.perf_counter()
    targets = design.library_targets
    robust = design.robustness if design.optimize_robust else None
    summary = _of_thicknesses(design.stack, _summary(design.targets))
    initial = float(summary(design.stack)[0])
    result = optimize_thicknesses(
        design.stack, targets, free=design.free, bounds_nm=(design.lower_nm, design.upper_nm),
        n_starts=design.starts, seed=design.seed, maxiter=design.max_steps, tol=design.gradient_tolerance,
        robust=None if design.needle else robust, method=design.method,
    )
    history: list = []
    free = design.free
    if design.needle:
        nd = design.needle
        bounds = (0.0, nd.max_thickness_nm)
        result, history = needle_design(
            result.stack, targets, list(nd.materials), iterations=nd.iterations, max_layers=nd.max_layers,
            bounds_nm=bounds, points_per_layer=nd.points_per_layer, min_thickness_nm=nd.min_thickness_nm,
            maxiter=design.max_steps, names=[f"N{m}" for m in range(len(nd.materials))], start=result,
            method=design.method,
        )
        stack = _merge_adjacent(result.stack)
        kept = [lay for lay in stack.layers if not (lay.coherent and float(lay.thickness) < nd.min_thickness_nm)]
        if len(kept) < len(stack.layers) or robust is not None:
            stack = _merge_adjacent(ls.Stack(stack.ambient, kept, stack.exit))
            result = optimize_thicknesses(stack, targets, bounds_nm=bounds, maxiter=design.max_steps,
                                          tol=design.gradient_tolerance, robust=robust, method=design.method)
    stack = _merge_adjacent(result.stack)
    if design.needle:
        free = tuple(i for i, lay in enumerate(stack.layers) if lay.coherent)
    if len(stack.layers) != len(design.stack.layers) or any(
            a.name != b.name or a.coherent != b.coherent for a, b in zip(stack.layers, design.stack.layers)):
        summary = _of_thicknesses(stack, _summary(design.targets))  # the needles changed the layout
    final_merit, rows = summary(stack)
    outcomes = _outcomes(design.targets, rows)
    yield_ = None
    if design.robustness is not None:
        yield_ = thickness_yield(stack, design.check_targets, design.robustness, free=free)
    return DesignOutcome(design, stack, initial, float(final_merit), result, history, outcomes, yield_,
                         time.perf_counter() - start_time)


# ------------------------------------------------------------------------------- reports
def _layer_name(outcome: DesignOutcome, layer) -> str:
    return outcome.design.layer_specs[layer.name][0]


def _band(wl: np.ndarray) -> str:
    if wl.size == 1:
        return f"{wl[0]:g} nm"
    return f"{wl[0]:g}–{wl[-1]:g} nm ({wl.size} wavelengths)"


def _angles_text(a) -> str:
    return ", ".join(f"{x:g}" for x in np.asarray(a).reshape(-1)) + "°"


def _target_line(i: int, t: TargetOutcome) -> str:
    part = t.target.parts[0]
    verdict = "met" if t.met else "NOT met"
    if t.target.is_colour:
        labs = ", ".join(f"({L:.2f}, {a:.2f}, {b:.2f})" for L, a, b in t.values)
        delta_e = ", ".join(f"{x:.4g}" for x in t.delta_e)
        return (f"target {i} {t.target.name!r}: colour of R under {part.colour_space.illuminant}, "
                f"{part.colour_space.observer.replace('Standard Observer', 'observer')}, "
                f"at {_angles_text(part.angle_deg)}: Lab {labs}; ΔE2000 {delta_e}; spec {t.target.spec}: {verdict}")
    q = part.quantity
    pol = "" if part.polarization == "natural" else f" ({part.polarization}-polarized)"
    v = t.values
    stats = f"{q} = {v.mean():.6g}" if v.size == 1 else f"mean {q} {v.mean():.6g}, min {v.min():.6g}, max {v.max():.6g}"
    return (f"target {i} {t.target.name!r}: {QUANTITY[q]}{pol} at {_band(np.asarray(part.wavelength_nm))}, "
            f"{_angles_text(part.angle_deg)}: {stats}; merit {t.merit:.6g}; spec {t.target.spec}: {verdict}")


def design_report(outcome: DesignOutcome) -> list[str]:
    """The design in a few lines: optimizer, merit before/after, layers, targets, yield."""
    d, r = outcome.design, outcome.result
    lines = [f"layerstack design of {d.path.name}" + (f": {d.description}" if d.description else "")]
    starts = f"{d.starts} start{'s' if d.starts > 1 else ''}" + (f" (seed {d.seed})" if d.starts > 1 else "")
    lines.append(f"optimizer: L-BFGS-B ({d.method}), {starts}; last refinement {r.message}")
    if d.needle:
        added = [d.needle.names[h["needle"][0]] for h in outcome.history[1:]]
        merits = " -> ".join(f"{h['merit']:.6g}" for h in outcome.history)
        lines.append(f"needle: {len(added)} insertion{'s' if len(added) != 1 else ''}"
                     + (f" ({', '.join(added)})" if added else " (none lowered the merit)")
                     + f" from candidates {', '.join(d.needle.names)}; merit {merits}")
    lines.append(f"merit: {outcome.initial_merit:.6g} (start) -> {outcome.merit:.6g} (design)")
    if d.optimize_robust and d.robustness is not None:
        lines.append(f"robust optimisation: expected merit under thickness errors {r.merit:.6g}")
    layers = []
    for layer in outcome.stack.layers:
        size = f"{float(layer.thickness):.2f} nm"
        layers.append(f"{_layer_name(outcome, layer)} {size}" + ("" if layer.coherent else " (incoherent)"))
    lines.append(f"layers ({len(layers)}, from the ambient): " + (" | ".join(layers) if layers else "none"))
    for i, t in enumerate(outcome.targets, 1):
        lines.append(_target_line(i, t))
    if outcome.yield_ is not None:
        rs = d.robustness
        errors = " + ".join(x for x in (f"{rs.sigma_nm:g} nm" if rs.sigma_nm else "",
                                        f"{100 * rs.relative:g} %" if rs.relative else "") if x)
        need = "" if d.min_yield is None else (
            f"; required >= {100 * d.min_yield:g} %: {'met' if outcome.yield_.fraction >= d.min_yield else 'NOT met'}")
        lines.append(f"yield: {100 * outcome.yield_.fraction:.4g} % of {rs.samples} draws within spec "
                     f"(thickness errors σ = {errors}, seed {rs.seed}){need}")
    lines.append("result: " + ("all targets met" if outcome.met else "targets NOT met"))
    return lines


# ---------------------------------------------------------------------------- the result file
def _rebase_tables(x, base_dir: Path, out_dir: Path):
    """Relative ``table = "file.csv"`` names, valid from ``base_dir``, made valid from ``out_dir``
    (relative when the two share a directory below the root, absolute otherwise)."""
    if isinstance(x, Mapping):
        out = {}
        for k, v in x.items():
            if k == "table" and isinstance(v, str) and not Path(v).is_absolute():
                table, here = (base_dir / v).resolve(), out_dir.resolve()
                shared = Path(os.path.commonpath([table, here]))
                v = str(table) if shared == Path(shared.anchor) else os.path.relpath(table, here)
            out[k] = _rebase_tables(v, base_dir, out_dir)
        return out
    if isinstance(x, list):
        return [_rebase_tables(v, base_dir, out_dir) for v in x]
    return x


def design_stack_dict(outcome: DesignOutcome, out_dir=".") -> dict:
    """The designed stack as a stack-file dict: the file's ambient and substrate, every layer's
    table as written (database references kept) with its designed thickness (plain number);
    needle layers named after their material; repeated names numbered."""
    d = outcome.design
    names = [_layer_name(outcome, layer) for layer in outcome.stack.layers]
    seen: dict = {}
    layers = []
    for layer, name in zip(outcome.stack.layers, names):
        if names.count(name) > 1:
            seen[name] = seen.get(name, 0) + 1
            name = f"{name} {seen[name]}"
        spec = d.layer_specs[layer.name][1]
        layers.append({"name": name, **{k: v for k, v in spec.items() if k in ("n", "k")},
                       "thickness_nm": float(layer.thickness),
                       **{k: v for k, v in spec.items() if k not in ("n", "k")}})
    out: dict = {}
    if d.description:
        out["description"] = d.description
    if "ambient" in d.raw:
        out["ambient"] = d.raw["ambient"]
    out["layers"] = layers
    out["substrate"] = d.raw["substrate"]
    return _rebase_tables(out, d.path.parent, Path(out_dir))


# ---------------------------------------------------------------------------------- plot
def _lab_to_xyz(lab: np.ndarray, white: np.ndarray) -> np.ndarray:
    """CIE 15:2004 eqs. (8.4)–(8.6) inverted: CIELAB → XYZ on the white's scale."""
    L, a, b = np.moveaxis(np.asarray(lab, float), -1, 0)
    fy = (L + 16.0) / 116.0
    f = np.stack([fy + a / 500.0, fy, fy - b / 200.0], axis=-1)
    delta = 6.0 / 29.0
    return np.asarray(white) * np.where(f > delta, f**3, 3 * delta**2 * (f - 4.0 / 29.0))


def _plot_grid(stack: ls.Stack, wl: np.ndarray) -> np.ndarray:
    """A dense grid around a target's band (±10 %, or ±20 % around one wavelength), kept inside
    the materials' data ranges."""
    lo, hi = float(wl[0]), float(wl[-1])
    pad = 0.1 * (hi - lo) if hi > lo else 0.2 * lo
    for a, b in ((max(lo - pad, 1.0), hi + pad), (lo, hi)):
        grid = np.linspace(a, b, 301) if b > a else np.array([a])
        try:
            ls.check_stack(stack, grid)
            return grid
        except LayerstackError:
            continue
    return np.asarray(wl)


def plot_design(outcome: DesignOutcome, path, *, title: str = "") -> Path:
    """PNG: each spectral target (design solid, start dashed, the spec shaded) and, for colour
    targets, swatches of the target and the design colour with their ΔE2000."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Rectangle

    spectral = [t for t in outcome.targets if not t.target.is_colour]
    colour = [t for t in outcome.targets if t.target.is_colour]
    rows = len(spectral) + (1 if colour else 0)
    fig = Figure(figsize=(8, 3.0 * rows + 0.6), dpi=110, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows, 1, squeeze=False)[:, 0]
    start = outcome.design.stack
    for ax, t in zip(axes, spectral):
        part = t.target.parts[0]
        wl = np.asarray(part.wavelength_nm)
        grid = _plot_grid(outcome.stack, wl)
        probe = SpectralTarget(jnp.asarray(grid), 0.0, quantity=part.quantity, angle_deg=part.angle_deg,
                               polarization=part.polarization)
        evaluate = _of_thicknesses(outcome.stack, probe.evaluate)
        design_q = np.asarray(evaluate(outcome.stack))
        if [lay.name for lay in start.layers] != [lay.name for lay in outcome.stack.layers]:
            evaluate = _of_thicknesses(start, probe.evaluate)  # needles changed the layout
        start_q = np.asarray(evaluate(start))
        for a, angle in enumerate(np.asarray(part.angle_deg)):
            style = dict(marker="o", ms=4) if grid.size == 1 else {}
            ax.plot(grid, design_q[a], "-", color=f"C{a}", lw=1.8, label=f"design {angle:g}°", **style)
            ax.plot(grid, start_q[a], "--", color=f"C{a}", lw=1.0, alpha=0.6, label=f"start {angle:g}°", **style)
        for p in t.target.parts:
            v = np.broadcast_to(np.asarray(p.value, float), wl.shape)
            if p.kind == "equal":
                tol = float(np.max(np.asarray(p.tolerance)))
                lo, hi = np.clip(v - tol, 0.0, 1.0), np.clip(v + tol, 0.0, 1.0)
                if wl.size <= 5:  # a few wavelengths: bars; a band: a shaded corridor
                    ax.errorbar(wl, v, yerr=(v - lo, hi - v), fmt="ks", ms=4, capsize=5, label="target ± tolerance")
                else:
                    ax.fill_between(wl, lo, hi, color="k", alpha=0.12, label="target ± tolerance")
                    ax.plot(wl, v, "k.", ms=4)
            else:
                ax.plot(wl, v, "k" + ("v" if p.kind == "below" else "^"), ms=5,
                        label=f"{'max' if p.kind == 'below' else 'min'}")
        ax.set_xlabel("wavelength (nm)")
        ax.set_ylabel(f"{part.quantity} ({QUANTITY[part.quantity]})")
        ax.set_ylim(bottom=0.0)
        ax.set_xlim(float(grid[0]) - (grid.size == 1), float(grid[-1]) + (grid.size == 1))
        ax.grid(True, alpha=0.3)
        pol = "" if part.polarization == "natural" else f", {part.polarization}-polarized"
        ax.set_title(f"{t.target.name}{pol}: {t.target.spec} — {'met' if t.met else 'NOT met'}", fontsize=10)
        ax.legend(loc="best", frameon=False, fontsize=8)
    if colour:
        ax = axes[-1]
        x = 0.0
        for t in colour:
            part = t.target.parts[0]
            cs = part.colour_space
            target_lab = np.broadcast_to(np.asarray(part.lab), t.values.shape)
            target_rgb = np.asarray(cs.XYZ_to_sRGB(_lab_to_xyz(target_lab, np.asarray(cs.white_XYZ)), clip=True))
            design_rgb = np.asarray(cs.XYZ_to_sRGB(_lab_to_xyz(t.values, np.asarray(cs.white_XYZ)), clip=True))
            for a, angle in enumerate(np.asarray(part.angle_deg)):
                ax.add_patch(Rectangle((x, 0.5), 1.0, 1.0, color=np.clip(target_rgb[a], 0, 1)))
                ax.add_patch(Rectangle((x, -0.5), 1.0, 1.0, color=np.clip(design_rgb[a], 0, 1)))
                ax.text(x + 0.5, -0.75, f"{t.target.name}\n{angle:g}°  ΔE00 {t.delta_e[a]:.2f}", ha="center",
                        va="top", fontsize=8)
                x += 1.3
        ax.text(-0.1, 1.0, "target", ha="right", va="center", fontsize=9)
        ax.text(-0.1, 0.0, "design", ha="right", va="center", fontsize=9)
        ax.set_xlim(-0.9, max(x, 1.3))
        ax.set_ylim(-1.6, 1.6)
        ax.set_aspect("equal")
        ax.axis("off")
        ax.set_title("colour targets (sRGB, clipped to the gamut)", fontsize=10)
    fig.suptitle(title or f"design of {outcome.design.path.name}: merit {outcome.initial_merit:.3g} → "
                 f"{outcome.merit:.3g}", fontsize=11)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    return path
