r"""Multi-start: the starting points (:func:`multistart_points`), the give-up rule of a start
solved after a converged one (:func:`give_up_rule`), the starts solved one after the other
(:func:`_multistart`) and the tie rule of the best start (:data:`TIE_RTOL`)."""

from __future__ import annotations

import math

import jax
import numpy as np

from layerstack_jax import progress_reporter

from ._compiled_fit import compiled_fit
from ._fit_output import FitOutput
from ._objective import Objective
from ._solver_options import NEVER, SolverOptions
from ._status import CONVERGED

__all__ = ["multistart_points", "TIE_RTOL", "STARTS_PER_CALL", "give_up_rule"]


def multistart_points(objective: Objective, starts: int, seed: int) -> np.ndarray:
    """``(starts, P)`` physical starting points: the objective's start first, then random
    draws — uniform between finite bounds, log-uniform within a factor 10 of the start above a
    lone lower (below a lone upper) bound, normal of width ``scale`` otherwise."""
    layout = objective.layout
    x0 = layout.x0
    rng = np.random.default_rng(seed)
    pts = np.tile(x0, (starts, 1))
    k = starts - 1
    if k <= 0:
        return pts
    lo, hi, s = layout.lower, layout.upper, layout.scale
    draw = pts[1:]
    b, lw, hg, fr = layout.both, layout.low, layout.high, layout.free
    draw[:, b] = lo[b] + (hi[b] - lo[b]) * rng.uniform(0.02, 0.98, (k, b.size))
    base = np.maximum(x0[lw] - lo[lw], 1e-3 * s[lw])
    draw[:, lw] = lo[lw] + base * 10.0 ** rng.uniform(-1, 1, (k, lw.size))
    base = np.maximum(hi[hg] - x0[hg], 1e-3 * s[hg])
    draw[:, hg] = hi[hg] - base * 10.0 ** rng.uniform(-1, 1, (k, hg.size))
    draw[:, fr] = x0[fr] + s[fr] * rng.normal(size=(k, fr.size))
    pts[1:] = draw
    return pts


#: Multi-start: costs within this relative difference of the lowest are the same minimum.
TIE_RTOL = 1e-9

#: Above this many starts a multi-start shows a progress bar by default.
STARTS_PER_CALL = 16

#: The multi-start give-up rule (:func:`give_up_rule`): a start is given up once it has taken
#: ``max(GIVE_UP_MIN_STEPS, GIVE_UP_STEPS × n)`` steps, n the steps of the best start converged
#: before it, while its cost is still above ``GIVE_UP_COST`` × that start's cost.
GIVE_UP_MIN_STEPS, GIVE_UP_STEPS, GIVE_UP_COST = 32, 3, 10.0


def give_up_rule(best_cost: float, best_steps: int) -> tuple:
    r"""``(steps, cost)`` of :meth:`fitting._least_squares.LevenbergMarquardt.terminate` for a start solved after a
    converged start of cost :math:`\tfrac12\|r\|^2` = ``best_cost`` found in ``best_steps``
    steps (:data:`GIVE_UP_MIN_STEPS`, :data:`GIVE_UP_STEPS`, :data:`GIVE_UP_COST`); :data:`fitting._solver_options.NEVER`
    while no start has converged.

    A start still a factor 10 above the best cost after three times the steps that start needed
    is descending into another, worse minimum or wandering (on benchmark E1, 10 of 16 starts
    ran 60–256 steps to costs 1e5–1e7 times the best, or to ``max_steps``): it cannot become the
    chosen start, so solving it further is wasted time. It is counted as not converged
    (:data:`fitting._status.ABANDONED`)."""
    if not np.isfinite(best_cost):
        return NEVER
    return max(GIVE_UP_MIN_STEPS, GIVE_UP_STEPS * int(best_steps)), GIVE_UP_COST * float(best_cost)


def _cost(out: FitOutput) -> np.ndarray:
    r""":math:`\tfrac12\|r\|^2` (data and penalty residuals) of NumPy fit output(s)."""
    lead = np.shape(out.status)
    data = sum(np.sum(np.asarray(r, float).reshape(lead + (-1,)) ** 2, axis=-1) for r in out.residuals)
    return 0.5 * (data + np.sum(np.asarray(out.penalty, float).reshape(lead + (-1,)) ** 2, axis=-1))


def _multistart(objective: Objective, o: SolverOptions, y0, args, progress) -> FitOutput:
    """All starts ``y0`` ``(S, P)`` (solver coordinates) on the same ``args``, solved one after
    the other by the fit's own compiled solver (:func:`fitting._compiled_fit.compiled_fit`, not a batched copy: no
    further compilation), each start after the first under the give-up rule of the best start
    converged so far (:func:`give_up_rule`; Levenberg–Marquardt). On a CPU that is also the
    fastest order: a vmapped block of starts costs per start about twice a single solve's step
    and runs until its slowest start ends (benchmark E1). ``progress`` as
    :func:`layerstack_jax.progress_reporter` (by default a bar above :data:`STARTS_PER_CALL`
    starts). NumPy output, one row per start."""
    n = y0.shape[0]
    fn = compiled_fit(objective, o, batched=False)
    update = progress_reporter(progress, n, desc="multi-start", unit="start", auto=n > STARTS_PER_CALL)
    outs = []
    best_cost, best_steps = math.inf, 0
    for i in range(n):
        out = jax.tree.map(np.asarray, fn(y0[i], args, objective.optics, give_up_rule(best_cost, best_steps)))
        cost = float(_cost(out))
        if int(out.status) == CONVERGED and cost < best_cost:
            best_cost, best_steps = cost, int(out.num_steps)
        outs.append(out)
        if update is not None:
            update(i + 1)
    return jax.tree.map(lambda *a: np.stack(a), *outs)
