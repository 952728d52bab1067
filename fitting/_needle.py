r"""The **needle method** (Tikhonravov, Trubetskov & DeBell, Appl. Opt. 35, 5493 (1996)) grows a
design: the derivative of :math:`M` with respect to the thickness of an infinitesimally thin
layer of a candidate material inserted at depth *z* — the needle function :math:`P(z)` — is
computed here exactly by automatic differentiation at zero needle thickness. Where
:math:`P(z) < 0` a needle lowers the merit; it is inserted at the most negative point and all
thicknesses are refined again.

Units: thicknesses in nm, wavelengths in nm, angles in degrees (these are the edges).
"""

from __future__ import annotations

from typing import Literal, NamedTuple, Optional, Sequence

import equinox as eqx
import jax
import numpy as np

import layerstack_jax as ls
from layerstack_jax import LayerstackError

from ._design import DesignResult, optimize_thicknesses
from ._design_targets import ColourTarget, merit

__all__ = ["NeedleScan", "needle_function", "insert_needle", "needle_design"]


class NeedleScan(NamedTuple):
    """Needle function sampled at candidate insertion points.

    ``layer``: shape ``(P,)``, index of the layer that would be split (``-1``: on top of the first
    layer); ``fraction``: ``(P,)`` depth inside that layer as a fraction of its thickness, from
    the side of the ambient; ``derivative``: ``(M, P)`` dM/dt at t = 0 for each candidate
    material ``M`` (negative: a needle helps), in 1/nm (dimensionless merit per nm of needle);
    ``fraction`` is dimensionless.
    """

    layer: np.ndarray
    fraction: np.ndarray
    derivative: np.ndarray


def _split_with_needle(stack: ls.Stack, j: int, f, material, t, name: str = "needle") -> ls.Stack:
    """Layer ``j`` split at fraction ``f`` with a needle of ``material``, thickness ``t`` inside
    (``j = -1``: needle on top of the first layer)."""
    layers = list(stack.layers)
    needle = ls.Layer(material, t, name=name)
    if j < 0:
        return ls.Stack(stack.ambient, [needle, *layers], stack.exit)
    host = layers[j]
    top = eqx.tree_at(lambda lay: lay.thickness, host, host.thickness * f)
    bottom = eqx.tree_at(lambda lay: lay.thickness, host, host.thickness * (1.0 - f))
    return ls.Stack(stack.ambient, [*layers[:j], top, needle, bottom, *layers[j + 1 :]], stack.exit)


def _common_grid(targets: Sequence) -> Optional[np.ndarray]:
    grids = [np.asarray(t.colour_space.wavelength_nm if isinstance(t, ColourTarget) else t.wavelength_nm)
             for t in targets]
    same = all(g.shape == grids[0].shape and np.array_equal(g, grids[0]) for g in grids)
    return grids[0] if same else None


def _sampled(material, grid) -> ls.Index:
    """``material`` as an :class:`~layerstack_jax.Index` sampled on ``grid`` (shape ``(W,)``)."""
    n = np.broadcast_to(np.asarray(ls.Layer(material, 0.0).index(grid)), grid.shape)
    return ls.Index(np.real(n).copy(), np.imag(n).copy())


def _uniform(stack: ls.Stack, grid) -> ls.Stack:
    """Same optics, every medium an Index on ``grid`` and no names: stacks that differ only in
    where a needle sits then share one pytree structure, so one compiled function serves all."""
    layers = [
        ls.Layer(_sampled(layer.index, grid), layer.thickness, coherent=layer.coherent, alpha=layer.alpha)
        for layer in stack.layers
    ]
    exit_ = eqx.tree_at(lambda e: e.index, stack.exit, _sampled(stack.exit.index, grid))
    return ls.Stack(_sampled(stack.ambient, grid), layers, exit_)


def needle_function(
    stack: ls.Stack, targets: Sequence, materials: Sequence, *, points_per_layer: int = 32
) -> NeedleScan:
    """Needle function P(z) = ∂M/∂t at t = 0 of a needle of each candidate material inserted
    at ``points_per_layer`` depths inside every coherent layer (and on top of the stack).

    Exact derivatives (reverse-mode autodiff at zero needle thickness). The candidate stacks are
    batched by pytree structure and differentiated in one vmapped call per structure — a single
    compilation when all targets share one wavelength grid (materials are then sampled on it).

    Returns a :class:`NeedleScan` with ``derivative`` of shape ``(M, P)`` in 1/nm (M candidate
    materials, P insertion points).
    """
    if not materials:
        raise LayerstackError("needle_function needs at least one candidate material")
    grid = _common_grid(targets)
    base = _uniform(stack, grid) if grid is not None else stack
    mats = [_sampled(m, grid) if grid is not None else m for m in materials]
    fractions = (np.arange(points_per_layer) + 0.5) / points_per_layer
    hosts = [-1] + [j for j, layer in enumerate(stack.layers) if layer.coherent]
    rows = []  # (layer, fraction, material index, needle position, candidate stack)
    for j in hosts:
        for f in [0.0] if j < 0 else fractions:
            for mi, m in enumerate(mats):
                cand = _split_with_needle(base, j, float(f), m, 0.0, name="" if grid is not None else "needle")
                rows.append((j, float(f), mi, j + 1 if j >= 0 else 0, cand))
    groups: dict = {}
    for i, row in enumerate(rows):
        leaves, treedef = jax.tree_util.tree_flatten(row[4])
        groups.setdefault((treedef, tuple(np.shape(x) for x in leaves)), []).append(i)
    derivative = np.empty(len(rows))
    for members in groups.values():
        batch = jax.tree_util.tree_map(lambda *xs: np.stack([np.asarray(x) for x in xs]), *[rows[i][4] for i in members])
        grads = jax.jit(jax.vmap(jax.grad(lambda st: merit(st, targets))))(batch)
        dd = np.stack([np.asarray(layer.thickness) for layer in grads.layers], axis=1)  # (C, layers)
        derivative[members] = dd[np.arange(len(members)), [rows[i][3] for i in members]]
    n_mat = len(materials)
    layer = np.array([r[0] for r in rows[::n_mat]])
    frac = np.array([r[1] for r in rows[::n_mat]])
    return NeedleScan(layer, frac, derivative.reshape(-1, n_mat).T)


def insert_needle(stack: ls.Stack, scan: NeedleScan, materials: Sequence, thickness_nm: float = 1.0,
                  names: Optional[Sequence[str]] = None):
    """Insert a needle of ``thickness_nm`` at the most negative point of ``scan``.

    The needle layer is named ``names[m]`` for material ``m`` (default ``"needle"``).
    Returns ``(new_stack, (material_index, layer, fraction, derivative))`` or ``(stack, None)``
    when no point has a negative derivative (the design is needle-optimal). ``layer`` and
    ``material_index`` are ints, ``fraction`` (dimensionless) and ``derivative`` (1/nm) scalars.
    """
    m, p = np.unravel_index(int(np.argmin(scan.derivative)), scan.derivative.shape)
    if scan.derivative[m, p] >= 0:
        return stack, None
    if names is not None and len(names) != len(materials):
        raise LayerstackError(f"insert_needle: {len(names)} names for {len(materials)} materials")
    j, f = int(scan.layer[p]), float(scan.fraction[p])
    name = "needle" if names is None else str(names[m])
    new = _split_with_needle(stack, j, f, materials[m], float(thickness_nm), name=name)
    new = ls.Stack(new.ambient, [_concrete(layer) for layer in new.layers], new.exit)
    return new, (int(m), j, f, float(scan.derivative[m, p]))


def _concrete(layer: ls.Layer) -> ls.Layer:
    return eqx.tree_at(lambda lay: lay.thickness, layer, float(np.asarray(layer.thickness)))


def _drop_thin_layers(stack: ls.Stack, min_nm: float) -> ls.Stack:
    """Remove coherent layers thinner than ``min_nm`` (a needle the refinement shrank away)."""
    kept = [layer for layer in stack.layers if not (layer.coherent and float(np.asarray(layer.thickness)) < min_nm)]
    return ls.Stack(stack.ambient, kept, stack.exit)


def needle_design(
    stack: ls.Stack,
    targets: Sequence,
    materials: Sequence,
    *,
    iterations: int = 5,
    max_layers: Optional[int] = None,
    bounds_nm=(0.0, 1000.0),
    points_per_layer: int = 32,
    min_thickness_nm: float = 0.5,
    maxiter: int = 500,
    names: Optional[Sequence[str]] = None,
    start: Optional[DesignResult] = None,
    method: Literal["jaxopt", "scipy"] = "jaxopt",
    progress: bool = True,
) -> tuple[DesignResult, list[dict]]:
    """Grow a design by the needle method: refine, scan the needle function, insert, repeat.

    Every coherent layer's thickness is free. Stops after ``iterations`` insertions, when no
    needle lowers the merit, or when ``max_layers`` would be exceeded. Needle layers are named
    ``names[m]`` after their material (default ``"needle"``). ``start``: a refinement of
    ``stack`` already made (e.g. multi-start, with per-layer bounds) to begin from instead of
    refining ``stack`` again; ``method``: of the refinements (:func:`optimize_thicknesses`).
    ``progress``: a progress bar (tqdm) over the refinements, with the current layer count and
    merit. The final design holds no coherent layer thinner than ``min_thickness_nm``: such
    layers are removed and the design refined again (a history entry with
    ``"removed_thin_layers"``). Returns the final :class:`DesignResult` and a history (one dict
    per step: layers, merit, inserted needle).

    Thicknesses in nm (``bounds_nm``: ``(lower, upper)``, scalars applied to every layer;
    ``min_thickness_nm``); merits are dimensionless scalars.
    """
    def refine(st):
        return optimize_thicknesses(st, targets, bounds_nm=bounds_nm, maxiter=maxiter, method=method)

    update = ls.progress_reporter(progress, iterations + 1, desc="needle design", unit="step")
    step = 0
    try:
        result = start if start is not None else refine(stack)
        history = [{"layers": len(result.stack.layers), "merit": result.merit, "needle": None}]
        step += 1
        _advance(update, step, result, "refined start")
        for _ in range(iterations):
            current = _drop_thin_layers(result.stack, min_thickness_nm)
            if max_layers is not None and len(current.layers) + 2 > max_layers:
                break
            scan = needle_function(current, targets, materials, points_per_layer=points_per_layer)
            candidate, needle = insert_needle(current, scan, materials, names=names)
            if needle is None:
                break
            refined = refine(candidate)
            if refined.merit >= result.merit:
                break
            result = refined
            history.append({"layers": len(result.stack.layers), "merit": result.merit, "needle": needle})
            step += 1
            _advance(update, step, result, "needle inserted")
        result = _enforce_min_thickness(result, min_thickness_nm, refine, history)
    finally:
        if update is not None:
            update(iterations + 1)  # done (early stops included): the bar closes
    return result, history


def _thin_layers(stack: ls.Stack, min_nm: float) -> list:
    return [i for i, layer in enumerate(stack.layers)
            if layer.coherent and float(np.asarray(layer.thickness)) < min_nm]


def _enforce_min_thickness(result: DesignResult, min_nm: float, refine, history: list) -> DesignResult:
    """The final design without coherent layers thinner than ``min_nm``: they are removed and
    the rest refined again, until none is left (each pass removes at least one layer)."""
    while _thin_layers(result.stack, min_nm):
        removed = len(_thin_layers(result.stack, min_nm))
        result = refine(_drop_thin_layers(result.stack, min_nm))
        history.append({"layers": len(result.stack.layers), "merit": result.merit, "needle": None,
                        "removed_thin_layers": removed})
    return result


def _advance(update, step: int, result: DesignResult, what: str) -> None:
    if update is not None:
        update(step, f"{what}: {len(result.stack.layers)} layers, merit {result.merit:.4g}")
