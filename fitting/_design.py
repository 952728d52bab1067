r"""Gradient-based coating design: layer thicknesses to spectral targets, needle insertion,
thickness-error yield and robust design.

The merit function is a weighted sum over targets of mean squared, tolerance-scaled deviations,

.. math::
    M(\mathbf d) = \sum_k \frac{w_k}{N_k}\sum_{i} \Big(\frac{Q_k(\lambda_i, \theta_i; \mathbf d)
    - Q^\text{target}_{k,i}}{\delta_{k,i}}\Big)^2,

with :math:`Q` a reflectance, transmittance or absorptance of the stack
(:func:`layerstack_jax.specular`, natural or polarized light). ``'below'`` / ``'above'`` targets
penalise only the side that violates the bound (a one-sided tolerance band), as thin-film
design programs do. :math:`M` is minimised over the free thicknesses within bounds by L-BFGS-B,
gradients by reverse-mode autodiff through the Rouard recursion — the bounded driver shared
with :func:`~fitting.fit` (:mod:`fitting._bounded`): jaxopt's, several starts run as one
vmapped solve, or SciPy's on the host (one compiled merit and gradient, quick to start).

The **needle method** (Tikhonravov, Trubetskov & DeBell, Appl. Opt. 35, 5493 (1996)) grows a
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
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Real

import layerstack_jax as ls
from layerstack_jax import LayerstackError

from ._bounded import BoundedSolution, compiled_lbfgsb, host_lbfgsb

__all__ = [
    "SpectralTarget",
    "ColourTarget",
    "merit",
    "DesignResult",
    "optimize_thicknesses",
    "NeedleScan",
    "needle_function",
    "insert_needle",
    "needle_design",
    "RobustSpec",
    "YieldResult",
    "with_thicknesses",
    "thickness_yield",
]


class SpectralTarget(eqx.Module):
    """A spectral design target.

    Attributes:
        wavelength_nm: wavelengths in nm, shape ``(W,)``.
        value: target values (R, T, A are dimensionless fractions), broadcastable to shape
            ``(A, W)`` (A = number of angles).
        tolerance: tolerance (> 0) of each point, broadcastable to ``(A, W)``: deviations are
            measured in units of it.
        quantity: ``'R'`` (reflectance), ``'T'`` (transmittance into the exit medium) or ``'A'``
            (absorptance 1 − R − T), for light from the ambient.
        angle_deg: ``(A,)`` angles of incidence in degrees (default normal incidence).
        polarization: ``'natural'`` (mean of s and p), ``'s'`` or ``'p'``.
        kind: ``'equal'`` (two-sided), ``'below'`` (Q ≤ value) or ``'above'`` (Q ≥ value).
        weight: weight of this target in the merit.
    """

    wavelength_nm: Float[Array, " W"] = eqx.field(converter=jnp.asarray)
    value: Real[Array, "..."] = eqx.field(converter=jnp.asarray)
    tolerance: Real[Array, "..."] = eqx.field(converter=jnp.asarray, default=0.01)
    quantity: Literal["R", "T", "A"] = eqx.field(static=True, default="R")
    angle_deg: Float[Array, " A"] = eqx.field(converter=lambda a: jnp.atleast_1d(jnp.asarray(a, float)), default=0.0)
    polarization: Literal["natural", "s", "p"] = eqx.field(static=True, default="natural")
    kind: Literal["equal", "below", "above"] = eqx.field(static=True, default="equal")
    weight: float = 1.0

    def __check_init__(self):
        if self.quantity not in ("R", "T", "A"):
            raise LayerstackError(f"SpectralTarget.quantity must be 'R', 'T' or 'A', got {self.quantity!r}")
        if self.polarization not in ("natural", "s", "p"):
            raise LayerstackError(
                f"SpectralTarget.polarization must be 'natural', 's' or 'p', got {self.polarization!r}"
            )
        if self.kind not in ("equal", "below", "above"):
            raise LayerstackError(f"SpectralTarget.kind must be 'equal', 'below' or 'above', got {self.kind!r}")
        if self.wavelength_nm.ndim != 1:
            raise LayerstackError(f"SpectralTarget.wavelength_nm must be 1-D, got shape {self.wavelength_nm.shape}")
        tol = np.asarray(self.tolerance)
        if np.any(~np.isfinite(tol)) or np.any(tol <= 0):
            raise LayerstackError("SpectralTarget.tolerance must be finite and > 0")
        if np.any(~np.isfinite(np.asarray(self.value))):
            raise LayerstackError("SpectralTarget.value contains NaN or infinite values")
        angles = np.asarray(self.angle_deg)
        if np.any(angles < 0) or np.any(angles >= 90):
            raise LayerstackError("SpectralTarget.angle_deg must lie in [0, 90) degrees")
        try:
            np.broadcast_shapes(np.shape(self.value), (angles.size, self.wavelength_nm.size))
            np.broadcast_shapes(np.shape(tol), (angles.size, self.wavelength_nm.size))
        except ValueError:
            raise LayerstackError(
                f"SpectralTarget.value {np.shape(self.value)} / tolerance {np.shape(tol)} do not broadcast to "
                f"(angles, wavelengths) = ({angles.size}, {self.wavelength_nm.size})"
            ) from None

    def evaluate(self, stack: ls.Stack) -> Float[Array, "A W"]:
        """The targeted quantity of ``stack``, shaped ``(A, W)``."""
        out = ls.specular(stack, self.wavelength_nm, self.angle_deg, both_sides=False)  # degrees
        R, T = out.R_front, out.T_front  # (A, 2, W)
        if self.polarization == "natural":
            R, T = 0.5 * (R[:, 0] + R[:, 1]), 0.5 * (T[:, 0] + T[:, 1])
        else:
            i = 0 if self.polarization == "s" else 1
            R, T = R[:, i], T[:, i]
        return {"R": R, "T": T, "A": 1.0 - R - T}[self.quantity]

    def deviation(self, stack: ls.Stack) -> Float[Array, "A W"]:
        """Signed violation in units of the tolerance (0 inside a one-sided band)."""
        x = (self.evaluate(stack) - self.value) / self.tolerance
        if self.kind == "below":
            return jnp.maximum(x, 0.0)
        if self.kind == "above":
            return jnp.minimum(x, 0.0)
        return x

    def merit(self, stack: ls.Stack):
        """``weight · mean(deviation²)``."""
        return self.weight * jnp.mean(self.deviation(stack) ** 2)

    def within_spec(self, stack: ls.Stack):
        """True where every point lies within its tolerance (|deviation| ≤ 1)."""
        return jnp.all(jnp.abs(self.deviation(stack)) <= 1.0)


class ColourTarget(eqx.Module):
    """A colour design target: the CIELAB colour of the stack's specular reflectance (natural
    light) under the illuminant and observer of ``colour_space``, at one or more angles.

    Attributes:
        colour_space: a :class:`layerstack_jax.ColourSpace` (its grid is the evaluation grid).
        lab: target L*, a*, b* (CIELAB, dimensionless), shape ``(3,)`` or ``(A, 3)``.
        angle_deg: ``(A,)`` angles of incidence, degrees.
        tolerance: ΔE2000 counted as one unit of deviation (within spec: ΔE2000 ≤ tolerance).
        weight: weight in the merit.
    """

    colour_space: ls.ColourSpace
    lab: Real[Array, "*A 3"] = eqx.field(converter=jnp.asarray)
    angle_deg: Float[Array, " A"] = eqx.field(converter=lambda a: jnp.atleast_1d(jnp.asarray(a, float)), default=0.0)
    tolerance: float = 1.0
    weight: float = 1.0

    def __check_init__(self):
        if np.shape(self.lab)[-1:] != (3,) or np.any(~np.isfinite(np.asarray(self.lab))):
            raise LayerstackError(f"ColourTarget.lab must be finite L*, a*, b* values (..., 3), got {np.shape(self.lab)}")
        if not float(self.tolerance) > 0:
            raise LayerstackError("ColourTarget.tolerance (ΔE2000) must be > 0")
        angles = np.asarray(self.angle_deg)
        if np.any(angles < 0) or np.any(angles >= 90):
            raise LayerstackError("ColourTarget.angle_deg must lie in [0, 90) degrees")

    def evaluate(self, stack: ls.Stack) -> Float[Array, "A 3"]:
        """CIELAB of the natural-light specular reflectance at each angle, ``(A, 3)``."""
        wl = jnp.asarray(self.colour_space.wavelength_nm)
        R = ls.specular(stack, wl, self.angle_deg, both_sides=False).R_front  # degrees
        return self.colour_space.Lab(0.5 * (R[:, 0] + R[:, 1]))

    def deviation(self, stack: ls.Stack) -> Float[Array, " A"]:
        """ΔE2000 to the target in units of the tolerance."""
        return ls.delta_e_2000(self.evaluate(stack), self.lab) / self.tolerance

    def merit(self, stack: ls.Stack):
        return self.weight * jnp.mean(self.deviation(stack) ** 2)

    def within_spec(self, stack: ls.Stack):
        return jnp.all(self.deviation(stack) <= 1.0)


def merit(stack: ls.Stack, targets: Sequence):
    """Total merit of ``stack`` against ``targets`` (:class:`SpectralTarget`,
    :class:`ColourTarget`): the sum of their ``merit`` — each a weighted mean of squared
    deviations in units of the target's tolerance, so a dimensionless scalar."""
    if not targets:
        raise LayerstackError("design needs at least one target")
    return sum(t.merit(stack) for t in targets)


# ------------------------------------------------------------------ free thicknesses
def _free_layers(stack: ls.Stack, free: Optional[Sequence[int]]) -> tuple[int, ...]:
    n = len(stack.layers)
    if free is None:
        free = [i for i, layer in enumerate(stack.layers) if layer.coherent]
    free = tuple(int(i) for i in free)
    for i in free:
        if not -n <= i < n:
            raise LayerstackError(f"free layer index {i} out of range for a stack of {n} layers")
    free = tuple(i % n for i in free)
    if len(set(free)) != len(free):
        raise LayerstackError(f"free layer indices repeat: {free}")
    if not free:
        raise LayerstackError("no free layer: the stack has no coherent layer and none was named in `free`")
    return free


def with_thicknesses(stack: ls.Stack, free: Sequence[int], d) -> ls.Stack:
    """``stack`` with the thicknesses of layers ``free`` replaced by ``d`` (nm, shape ``(F,)``)."""
    return eqx.tree_at(
        lambda s: tuple(s.layers[i].thickness for i in free), stack, tuple(d[k] for k in range(len(free)))
    )


def _bounds(bounds, n_free: int):
    lo, hi = (np.broadcast_to(np.asarray(b, float), (n_free,)).copy() for b in bounds)
    if np.any(lo < 0):
        raise LayerstackError(f"thickness bounds must be >= 0 nm, got lower bounds {lo}")
    if np.any(hi <= lo):
        raise LayerstackError(f"thickness bounds inverted or empty: lower {lo}, upper {hi}")
    return lo, hi


class DesignResult(NamedTuple):
    """Outcome of a thickness optimisation.

    ``stack``: the best design; ``thickness_nm``: its free thicknesses in nm, shape ``(F,)``; ``free``: their
    layer indices; ``merit`` and ``initial_merit``: merit of the best design and of the start;
    ``start_merits``: final merit of every start ``(S,)``; ``n_steps``: iterations of the best
    start; ``converged``: the best start met the tolerance before ``maxiter``; ``message``.
    Merits are dimensionless scalars (see :func:`merit`).
    """

    stack: ls.Stack
    thickness_nm: np.ndarray
    free: tuple
    merit: float
    initial_merit: float
    start_merits: np.ndarray
    n_steps: int
    converged: bool
    message: str


def _messages(sol: BoundedSolution, maxiter: int, tol: float, driver: str) -> list:
    return [
        f"converged in {int(k)} iterations ({driver}; projected-gradient norm {g:.1e}, tol {tol:g})" if ok
        else f"NOT converged: {int(k)} iterations (maxiter {maxiter}, {driver}), projected-gradient norm {g:.1e} > tol {tol:g}"
        for k, g, ok in zip(np.atleast_1d(sol.num_steps), np.atleast_1d(sol.gradient_norm), np.atleast_1d(sol.converged))
    ]


def _solve_compiled(total, X0, lo, hi, maxiter: int, tol: float) -> BoundedSolution:
    """All starts ``X0`` ``(S, F)`` in one compiled, vmapped L-BFGS-B solve
    (:func:`fitting._bounded.compiled_lbfgsb`)."""
    run = compiled_lbfgsb(lambda x: total(x), maxiter, tol)
    lower, upper = jnp.asarray(lo), jnp.asarray(hi)

    @jax.jit
    def solve_all(X):
        if X.shape[0] == 1:  # one start: no vmap (compiles ~1.5x faster)
            return jax.tree.map(lambda a: a[None], run(X[0], lower, upper))
        return jax.vmap(lambda x0: run(x0, lower, upper))(X)

    return BoundedSolution(*(np.asarray(a) for a in solve_all(jnp.asarray(X0))))


def optimize_thicknesses(
    stack: ls.Stack,
    targets: Sequence,
    *,
    free: Optional[Sequence[int]] = None,
    bounds_nm=(0.0, 1000.0),
    starts_nm=None,
    n_starts: int = 1,
    seed: int = 0,
    maxiter: int = 500,
    tol: float = 1e-9,
    robust: Optional["RobustSpec"] = None,
    method: Literal["jaxopt", "scipy"] = "jaxopt",
) -> DesignResult:
    """Minimise the merit over the thicknesses of layers ``free`` within ``bounds_nm``.

    Args:
        stack: starting design (its thicknesses are the first start).
        targets: :class:`SpectralTarget` list.
        free: indices of the layers whose thickness varies (default: every coherent layer).
        bounds_nm: ``(lower, upper)`` in nm, scalars or one per free layer.
        starts_nm: optional extra starts ``(S, F)`` in nm; with ``n_starts > 1`` and no
            ``starts_nm``, uniform random starts within the bounds are added (``seed``).
        maxiter, tol: L-BFGS-B iteration cap and tolerance on the projected gradient.
        robust: optimise the expected merit under random thickness errors (:class:`RobustSpec`).
        method: ``"jaxopt"``: all starts run in one vmapped, compiled L-BFGS-B solve (jaxopt) —
            for many starts or an accelerator, at ~10 s or more of compilation; ``"scipy"``:
            SciPy's L-BFGS-B on the host, start after start, with the merit and its gradient
            compiled once — seconds to start, for small designs and the command line.

    The best start is returned.
    """
    if method not in ("jaxopt", "scipy"):
        raise LayerstackError(f"optimize_thicknesses: method must be 'jaxopt' or 'scipy', got {method!r}")
    free = _free_layers(stack, free)
    lo, hi = _bounds(bounds_nm, len(free))
    d0 = np.array([float(np.asarray(stack.layers[i].thickness)) for i in free])
    if np.any(d0 < lo) or np.any(d0 > hi):
        raise LayerstackError(f"starting thicknesses {d0} nm lie outside the bounds [{lo}, {hi}]")
    starts = [d0[None]]
    if starts_nm is not None:
        s = np.atleast_2d(np.asarray(starts_nm, float))
        if s.shape[1] != len(free):
            raise LayerstackError(f"starts_nm must be shaped (S, {len(free)}), got {s.shape}")
        starts.append(np.clip(s, lo, hi))
    elif n_starts > 1:
        rng = np.random.default_rng(seed)
        starts.append(rng.uniform(lo, hi, (n_starts - 1, len(free))))
    X0 = np.concatenate(starts)
    scale = 100.0  # nm: variables of order one for L-BFGS-B

    def total(x):
        # The model sees thicknesses >= 0 and finite: under vmap, the lanes of starts that have
        # already stopped keep being evaluated on whatever they hold, and the stack's own checks
        # (thickness >= 0 and finite) would stop the whole solve. A start whose iterate is NaN is
        # still reported as not converged (BoundedSolution checks its x).
        d = jnp.maximum(jnp.where(jnp.isfinite(x), x, 0.0) * scale, 0.0)
        if robust is None:
            return merit(with_thicknesses(stack, free, d), targets)
        return _expected_merit(stack, targets, free, d, robust)

    if method == "jaxopt":
        sol = _solve_compiled(total, X0 / scale, lo / scale, hi / scale, maxiter, tol)
    else:
        sol = host_lbfgsb(total, X0 / scale, lo / scale, hi / scale, maxiter, tol)
    messages = _messages(sol, maxiter, tol, "jaxopt L-BFGS-B" if method == "jaxopt" else "SciPy L-BFGS-B")
    initial = float(total(jnp.asarray(X0[0] / scale)))
    values = np.where(np.isfinite(sol.value), sol.value, np.inf)
    best = int(np.argmin(values))
    d_best = sol.x[best] * scale
    iters, ok = sol.num_steps, sol.converged
    return DesignResult(
        stack=with_thicknesses(stack, free, jnp.asarray(d_best)),
        thickness_nm=d_best,
        free=free,
        merit=float(values[best]),
        initial_merit=float(initial),
        start_merits=values,
        n_steps=int(iters[best]),
        converged=bool(ok[best]),
        message=messages[best],
    )


# ------------------------------------------------------------------ needle method
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


# ------------------------------------------------------------------ tolerances and yield
class RobustSpec(NamedTuple):
    """Random thickness errors: Gaussian, ``sigma_nm`` absolute plus ``relative`` × thickness,
    ``samples`` fixed draws (common random numbers: the robust merit stays smooth).

    ``sigma_nm`` in nm, ``relative`` a dimensionless fraction; the draws are standard normals of
    shape ``(samples, F)`` (F free layers), seeded by ``seed``; perturbed thicknesses are
    clipped at 0."""

    sigma_nm: float = 0.0
    relative: float = 0.0
    samples: int = 64
    seed: int = 0


def _perturbations(spec: RobustSpec, n_free: int) -> np.ndarray:
    if spec.sigma_nm < 0 or spec.relative < 0 or spec.samples < 1:
        raise LayerstackError("thickness errors need sigma_nm >= 0, relative >= 0, samples >= 1")
    return np.random.default_rng(spec.seed).standard_normal((spec.samples, n_free))


def _perturbed(d, z, spec: RobustSpec):
    return jnp.maximum(d + z * (spec.sigma_nm + spec.relative * d), 0.0)


def _expected_merit(stack, targets, free, d, spec: RobustSpec):
    z = jnp.asarray(_perturbations(spec, len(free)))
    return jnp.mean(jax.vmap(lambda zi: merit(with_thicknesses(stack, free, _perturbed(d, zi, spec)), targets))(z))


class YieldResult(NamedTuple):
    """Monte-Carlo of thickness errors: ``fraction`` of draws within spec (a dimensionless
    scalar in [0, 1]), per-draw ``merits`` (dimensionless) and ``within`` flags, each of shape
    ``(samples,)``."""

    fraction: float
    merits: np.ndarray
    within: np.ndarray


def thickness_yield(
    stack: ls.Stack,
    targets: Sequence,
    errors: RobustSpec,
    *,
    free: Optional[Sequence[int]] = None,
) -> YieldResult:
    """Fraction of manufactured designs within spec (every target point within its tolerance)
    when the thicknesses of layers ``free`` carry random errors ``errors`` (one vmapped call).

    ``errors``: a :class:`RobustSpec` (``sigma_nm`` in nm). Returns a :class:`YieldResult`: the
    fraction is a dimensionless scalar in [0, 1]; ``merits`` and ``within`` have shape
    ``(samples,)``."""
    free = _free_layers(stack, free)
    d = jnp.asarray([float(np.asarray(stack.layers[i].thickness)) for i in free])
    z = jnp.asarray(_perturbations(errors, len(free)))

    @jax.jit
    def one(zi):
        st = with_thicknesses(stack, free, _perturbed(d, zi, errors))
        ok = jnp.all(jnp.stack([t.within_spec(st) for t in targets]))
        return merit(st, targets), ok

    merits, within = (np.asarray(a) for a in jax.vmap(one)(z))
    return YieldResult(float(np.mean(within)), merits, within)
