r"""Free parameters resolved on a stack and packed into one vector.

:func:`resolve_parameter` finds a :class:`~fitting.Parameter`'s leaf in a stack (layers by name or
position, an element of an array leaf, a field of the datasets' geometries), takes its start,
bounds, scale and spectral basis (:class:`ResolvedParameter`).

Packing (:class:`Layout`): all coefficients, parameters in order, each flattened row-major
(sample, coefficient), form the physical vector ``x``. Unconstrained solvers work on ``u`` with
(:func:`Layout.to_physical`)

* both bounds finite: :math:`x = l + (h-l)\,\sigma(u)` (logistic);
* lower bound only: :math:`x = l + s\,e^{u}` (a log scale: thicknesses and α span decades);
* upper bound only: :math:`x = h - s\,e^{u}`;
* none: :math:`x = s\,u`,

with :math:`s` the parameter's scale (its starting magnitude). A bound is never reached by a
transform; when the optimum lies on a bound use the bounded solver (jaxopt L-BFGS-B), which works on
:math:`z = x/s` and keeps bounds exactly.
"""

from __future__ import annotations

import dataclasses
from typing import Optional, Sequence

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from layerstack_jax import (
    Cauchy,
    Index,
    LayerstackError,
    Sellmeier,
    Stack,
    as_spectrum,
    leaf_role_at,
)

from ._parameters import DEFAULT_BOUNDS, Parameter, bspline_basis, is_instrument_path

__all__ = ["ResolvedParameter", "resolve_parameter", "Layout", "canonical_path", "element_of", "get_path"]

#: Fraction of the range (or scale) by which a start on a bound is moved inside it.
_NUDGE = 1e-3


def _instrument_parameter(p: Parameter, datasets: Sequence) -> "ResolvedParameter":
    """Resolve a ``("datasets", which, field)`` parameter against the datasets of a fit: the
    canonical path ``("datasets", (i, ...), field)``, a scalar start, bounds and scale."""
    label = p.label
    if len(p.path) != 3 or not isinstance(p.path[2], str):
        raise LayerstackError(f"free parameter {label!r}: an instrument path is ('datasets', index | indices | 'all', "
                              f"field), got {p.path!r}")
    if p.per_sample or p.basis is not None:
        raise LayerstackError(f"free parameter {label!r}: a number of the instrument is one scalar "
                              "(no per_sample, no basis)")
    which, field = p.path[1], p.path[2]
    has = [i for i, ds in enumerate(datasets) if hasattr(ds.geometry, field) and not field.startswith("_")]
    if which == "all":
        which = tuple(has)
        if not which:
            raise LayerstackError(f"free parameter {label!r}: no dataset's geometry has a field {field!r}")
    which = (which,) if isinstance(which, (int, np.integer)) else tuple(which)
    for i in which:
        if not isinstance(i, (int, np.integer)) or not 0 <= i < len(datasets):
            raise LayerstackError(f"free parameter {label!r}: the fit has {len(datasets)} dataset(s), no dataset {i!r}")
        if i not in has:
            raise LayerstackError(f"free parameter {label!r}: dataset {i} ({type(datasets[i].geometry).__name__}) has "
                                  f"no field {field!r}")
    if p.value is not None:
        x0 = np.asarray(p.value, dtype=float)
    else:
        starts = {float(np.asarray(getattr(datasets[i].geometry, field), dtype=float)) for i in which}
        if len(starts) != 1:
            raise LayerstackError(f"free parameter {label!r}: datasets {which} hold different {field} values "
                                  f"{sorted(starts)}; give value=")
        x0 = np.asarray(starts.pop())
    if x0.shape != () or not np.isfinite(x0):
        raise LayerstackError(f"free parameter {label!r}: value must be one finite number, got {p.value!r}")
    x0 = x0.reshape(1)
    dlo, dhi = DEFAULT_BOUNDS[p.kind]
    lo, hi = _broadcast(p, "lower bound", p.lower, 1, dlo), _broadcast(p, "upper bound", p.upper, 1, dhi)
    if lo[0] >= hi[0] or not lo[0] <= x0[0] <= hi[0]:
        raise LayerstackError(f"free parameter {label!r}: start {x0[0]:g} and bounds [{lo[0]:g}, {hi[0]:g}] "
                              "are inconsistent")
    span = hi - lo
    scale = (_broadcast(p, "scale", p.scale, 1, 1.0) if p.scale is not None
             else np.where(x0 != 0, np.abs(x0), np.where(np.isfinite(span), span, 1.0)))
    return ResolvedParameter(p, ("datasets", which, field), None, x0, lo, hi, scale, (), np.zeros(1, bool))


# ---------------------------------------------------------------- resolution on a stack
def _find_layer(stack: Stack, ref, label: str) -> int:
    names = [layer.name for layer in stack.layers]
    if isinstance(ref, (int, np.integer)) and not isinstance(ref, bool):
        i = int(ref)
        if not -len(names) <= i < len(names):
            raise LayerstackError(f"free parameter {label!r}: the stack has {len(names)} layer(s), no layer {ref}")
        return i % len(names)
    if isinstance(ref, str):
        hits = [i for i, n in enumerate(names) if n == ref]
        if not hits:
            raise LayerstackError(f"free parameter {label!r}: the stack has no layer named {ref!r} (layers: {names})")
        if len(hits) > 1:
            raise LayerstackError(f"free parameter {label!r}: several layers are named {ref!r}; give the position")
        return hits[0]
    raise LayerstackError(f"free parameter {label!r}: a layer is given by position or name, got {ref!r}")


def canonical_path(stack: Stack, p: Parameter) -> tuple:
    """The path with layer names replaced by positions, checked against the stack."""
    label = p.label
    path = p.path
    if path[0] == "layers":
        if len(path) < 3:
            raise LayerstackError(f"free parameter {label!r}: path {path!r} names no field of a layer")
        path = ("layers", _find_layer(stack, path[1], label), *path[2:])
    elif path[0] not in ("ambient", "exit"):
        raise LayerstackError(f"free parameter {label!r}: path must start with 'layers', 'ambient' or 'exit', got {path!r}")
    node = stack
    where = "stack"
    for i, part in enumerate(path):
        if isinstance(part, (int, np.integer)) and not isinstance(part, bool):
            node = _item(node, int(part), i == len(path) - 1, where, label)
            where += f"[{part}]"
            continue
        if not hasattr(node, part) or part.startswith("_"):
            fields = [f.name for f in dataclasses.fields(node)] if dataclasses.is_dataclass(node) else []
            what = f"the stack's exit is a {node.label}," if node is stack.exit else f"{where} ({type(node).__name__})"
            raise LayerstackError(
                f"free parameter {label!r}: {what} has no field {part!r}"
                + (f" (fields: {fields})" if fields else "")
            )
        node = getattr(node, part)
        where += f".{part}"
    if isinstance(node, eqx.Module) and not hasattr(node, "__call__"):
        raise LayerstackError(f"free parameter {label!r}: {where} is a {type(node).__name__}, not a number")
    if path[-1] == "alpha" and path[0] == "layers" and stack.layers[path[1]].coherent:
        raise LayerstackError(
            f"free parameter {label!r}: layer {path[1]} is coherent; alpha is for incoherent layers (fit k instead)"
        )
    field = path[:-1] if element_of(stack, path) is not None else path
    if field[-2:-1] == ("index",) and field[-1] in ("n", "k", "A", "B", "C"):
        mat = get_path(stack, field[:-1])
        allowed = {Index: ("n", "k"), Cauchy: ("A", "B", "C", "k"), Sellmeier: ("B", "C", "k")}
        if type(mat) in allowed and field[-1] not in allowed[type(mat)]:
            raise LayerstackError(
                f"free parameter {label!r}: {type(mat).__name__} has no coefficient {field[-1]!r} "
                f"(it has {allowed[type(mat)]})"
            )
    return path


def _is_array_leaf(node) -> bool:
    return hasattr(node, "shape") and not isinstance(node, eqx.Module)


def _item(node, i: int, last: bool, where: str, label: str):
    """``node[i]`` on a path: an entry of a list or tuple of the stack (layers, the materials of
    an effective medium), or — last on the path only — one element of a 1-D array leaf (a
    Sellmeier B or C, an oscillator list): ``("layers", "glass", "index", "B", 0)``."""
    if isinstance(node, (list, tuple)):
        if not 0 <= i < len(node):
            raise LayerstackError(f"free parameter {label!r}: {where} has {len(node)} entries, no entry {i}")
        return node[i]
    if isinstance(node, (int, float)):
        raise LayerstackError(f"free parameter {label!r}: {where} is a number, not a list: free the number itself")
    if not _is_array_leaf(node):
        raise LayerstackError(f"free parameter {label!r}: {where} ({type(node).__name__}) has no entry {i}")
    if not last:
        raise LayerstackError(f"free parameter {label!r}: an element index ({where}[{i}]) must end the path")
    if np.ndim(node) != 1:
        raise LayerstackError(f"free parameter {label!r}: {where} has shape {np.shape(node)}; an element index "
                              "addresses a list of coefficients (1-D)" + ("" if np.ndim(node) else
                                                                          ": free the number itself"))
    if not 0 <= i < np.shape(node)[0]:
        raise LayerstackError(f"free parameter {label!r}: {where} has {np.shape(node)[0]} elements, no element {i}")
    return node[i]


def element_of(stack: Stack, path: tuple) -> Optional[int]:
    """The element index when a canonical ``path`` ends inside an array leaf (:func:`_item`), else None."""
    if not path or not isinstance(path[-1], (int, np.integer)) or isinstance(path[-1], bool):
        return None
    return int(path[-1]) if _is_array_leaf(get_path(stack, path[:-1])) else None


def get_path(tree, path: tuple):
    node = tree
    for part in path:
        node = node[part] if isinstance(part, int) else getattr(node, part)
    return node


def _current_leaf(stack: Stack, path: tuple, wavelength_nm: np.ndarray, spectral: bool):
    leaf = get_path(stack, path)
    if leaf is None:
        return None
    if callable(leaf) and not isinstance(leaf, (np.ndarray,)) and not hasattr(leaf, "shape"):
        return np.asarray(as_spectrum(leaf, wavelength_nm), dtype=float)
    a = np.asarray(leaf, dtype=float)
    if spectral and a.ndim == 0:
        a = np.full(wavelength_nm.shape, float(a))
    return a


@dataclasses.dataclass(frozen=True, eq=False)
class ResolvedParameter:
    """A parameter checked against a stack and a wavelength grid.

    ``basis``: ``(wl, m)`` or None; ``x0``: starting coefficients ``(m,)`` or ``(samples, m)``;
    ``lower``, ``upper``, ``scale``: ``(m,)``; ``leaf_shape``: shape of the value put in the stack;
    ``element``: when the path ends with an element index into an array leaf (a Sellmeier B
    term), that index (the value is one number, put at ``leaf[element]``), else None.
    """

    parameter: Parameter
    path: tuple
    basis: Optional[np.ndarray]
    x0: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    scale: np.ndarray
    leaf_shape: tuple
    fixed: np.ndarray
    element: Optional[int] = None

    @property
    def leaf_path(self) -> tuple:
        """Path of the stack leaf this parameter changes (the array, for an element)."""
        return self.path if self.element is None else self.path[:-1]

    @property
    def name(self) -> str:
        return self.parameter.label

    @property
    def m(self) -> int:
        return self.x0.shape[-1]

    @property
    def per_sample(self) -> bool:
        return self.parameter.per_sample

    @property
    def size(self) -> int:
        return self.x0.size

    @property
    def public_shape(self) -> tuple:
        """Shape of the value reported to users: ``()`` / ``(samples,)`` for a one-number leaf,
        else the coefficient shape ``(m,)`` / ``(samples, m)``."""
        if self.basis is None and self.leaf_shape == ():
            return self.x0.shape[:-1]
        return self.x0.shape

    def leaf(self, coefficients):
        """Value placed in the stack: ``B c`` for a spectral parameter, else the coefficients
        (a scalar for a one-number leaf)."""
        if self.basis is not None:
            return jnp.asarray(self.basis) @ coefficients
        return coefficients.reshape(self.leaf_shape)

    def spectrum(self, coefficients) -> np.ndarray:
        c = np.asarray(coefficients)
        return c @ self.basis.T if self.basis is not None else c


def _broadcast(p: Parameter, what: str, v, m: int, default: float) -> np.ndarray:
    if v is None:
        v = default
    a = np.asarray(v, dtype=float)
    if a.ndim == 0:
        a = np.full(m, float(a))
    if a.shape != (m,):
        raise LayerstackError(f"free parameter {p.label!r}: {what} must be a number or {m} values, got shape {a.shape}")
    if np.any(np.isnan(a)):
        raise LayerstackError(f"free parameter {p.label!r}: {what} is NaN")
    return a


def resolve_parameter(p: Parameter, stack: Stack, wavelength_nm: np.ndarray, n_samples: int,
                      datasets: Sequence = ()) -> ResolvedParameter:
    """Check ``p`` against the stack and grid (or, for an :func:`instrument` path, against the
    ``datasets`` of the fit); build its basis, start, bounds and scale."""
    if is_instrument_path(p.path):
        return _instrument_parameter(p, datasets)
    label = p.label
    path = canonical_path(stack, p)
    wl = np.asarray(wavelength_nm, float)
    leaf = _current_leaf(stack, path, wl, spectral=p.basis is not None)
    basis = p.basis
    if (basis is None and leaf is not None and leaf.ndim == 1 and leaf.shape == wl.shape
            and element_of(stack, path) is None and leaf_role_at(stack, path).per_wavelength):
        basis = "free"  # the stack holds a spectrum: fit it per wavelength unless told otherwise
    if isinstance(basis, str):
        B = np.eye(wl.size)
    elif isinstance(basis, (int, np.integer)):
        B = bspline_basis(wl, int(basis))
    elif basis is None:
        B = None
    else:
        B = np.asarray(basis, dtype=float)
        if B.ndim != 2 or B.shape[0] != wl.size:
            raise LayerstackError(
                f"free parameter {label!r}: basis must be a ({wl.size}, m) matrix on the model grid, got shape {B.shape}"
            )
    # starting value
    if p.value is not None:
        x0 = np.asarray(p.value, dtype=float)
        if B is None and leaf is not None and leaf.ndim == 1 and x0.ndim == 0:
            x0 = np.full(leaf.shape, float(x0))
    else:
        if leaf is None:
            raise LayerstackError(f"free parameter {label!r}: the stack holds no value here; give value=")
        if B is not None:
            v = np.broadcast_to(leaf, wl.shape) if leaf.ndim == 0 else leaf
            if v.shape != wl.shape:
                raise LayerstackError(f"free parameter {label!r}: stack value has shape {v.shape}, grid has {wl.shape}")
            x0 = np.linalg.lstsq(B, v, rcond=None)[0]
        else:
            x0 = leaf
    if B is not None:
        leaf_shape = wl.shape
        m = B.shape[1]
    else:
        if leaf is not None:
            leaf_shape = np.shape(leaf)
        elif p.per_sample and x0.ndim >= 1 and x0.shape[0] == n_samples:
            leaf_shape = x0.shape[1:]
        else:
            leaf_shape = x0.shape
        m = int(np.prod(leaf_shape)) if leaf_shape else 1
    if B is not None and x0.ndim == 0:
        x0 = np.linalg.lstsq(B, np.full(wl.shape, float(x0)), rcond=None)[0]
    # per-sample broadcasting
    if p.per_sample:
        if x0.ndim == 0 or x0.shape == (m,) and not (m == 1 and x0.shape == (n_samples,)):
            x0 = np.broadcast_to(np.reshape(x0, (1, m)), (n_samples, m)).copy()
        elif x0.shape == (n_samples,) and m == 1:
            x0 = x0.reshape(n_samples, 1)
        elif B is not None and x0.shape == (n_samples, wl.size) and B.shape[1] != wl.size:
            x0 = np.linalg.lstsq(B, x0.T, rcond=None)[0].T
        if x0.shape != (n_samples, m):
            raise LayerstackError(
                f"free parameter {label!r}: per-sample value must be shaped ({n_samples},) or ({n_samples}, {m}), got {x0.shape}"
            )
    else:
        x0 = np.reshape(x0, -1) if x0.size == m else x0
        if x0.shape != (m,):
            raise LayerstackError(f"free parameter {label!r}: value must be a number or {m} values, got shape {x0.shape}")
    if np.any(~np.isfinite(x0)):
        raise LayerstackError(f"free parameter {label!r}: starting value is not finite")
    dlo, dhi = DEFAULT_BOUNDS[p.kind]
    lo = _broadcast(p, "lower bound", p.lower, m, dlo)
    hi = _broadcast(p, "upper bound", p.upper, m, dhi)
    bad = lo >= hi
    if np.any(bad):
        i = int(np.argmax(bad))
        raise LayerstackError(
            f"free parameter {label!r}: bounds inverted or empty (lower {lo[i]:g} >= upper {hi[i]:g}"
            + (f" for coefficient {i}" if m > 1 else "") + ")"
        )
    outside = (x0 < lo) | (x0 > hi)
    if np.any(outside):
        raise LayerstackError(
            f"free parameter {label!r}: starting value {x0[outside].ravel()[0]:g} outside its bounds "
            f"[{np.broadcast_to(lo, x0.shape)[outside].ravel()[0]:g}, {np.broadcast_to(hi, x0.shape)[outside].ravel()[0]:g}]"
        )
    if p.scale is not None:
        scale = _broadcast(p, "scale", p.scale, m, 1.0)
        if np.any(scale <= 0):
            raise LayerstackError(f"free parameter {label!r}: scale must be > 0")
    else:
        mag = np.abs(x0).reshape(-1, m).max(axis=0)
        span = np.where(np.isfinite(hi - lo), hi - lo, 0.0)
        scale = np.where(mag > 0, mag, np.where(span > 0, span, 1.0))
        if B is not None:  # coefficients of one spectrum share one scale
            scale = np.full(m, scale.max())
    if p.fixed is None:
        fixed = np.zeros(x0.shape, bool)
    else:
        f = np.asarray(p.fixed)
        if f.dtype != bool:
            raise LayerstackError(f"free parameter {label!r}: fixed must be a boolean mask")
        if p.per_sample and f.shape == (n_samples,):
            f = f[:, None]
        try:
            fixed = np.broadcast_to(f, x0.shape).copy()
        except ValueError:
            raise LayerstackError(f"free parameter {label!r}: fixed mask shaped {f.shape} does not match the value {x0.shape}") from None
    element = element_of(stack, path)
    if element is not None and (B is not None or leaf_shape != ()):
        raise LayerstackError(f"free parameter {label!r}: an element of a list is one number (no basis)")
    return ResolvedParameter(p, path, B, x0, lo, hi, scale, leaf_shape, fixed, element)


# ------------------------------------------------------------------------------ layout
class Layout:
    """Flat packing of resolved parameters and the bound transforms (module docstring)."""

    def __init__(self, params: Sequence[ResolvedParameter], n_samples: int):
        self.params = tuple(params)
        self.n_samples = n_samples
        # the stack leaves changed, each with [(parameter index, element or None for the whole leaf)]
        self._targets: dict = {}
        # the geometry fields changed: (dataset, field) -> parameter index
        self._instrument: dict = {}
        for i, p in enumerate(self.params):
            if is_instrument_path(p.path):
                for k in p.path[1]:
                    if (k, p.path[2]) in self._instrument:
                        raise LayerstackError(f"free parameter {p.name!r}: {p.path[2]} of dataset {k} is freed twice")
                    self._instrument[(k, p.path[2])] = i
                continue
            taken = self._targets.setdefault(p.leaf_path, [])
            if any(e is None or p.element is None or e == p.element for _, e in taken):
                raise LayerstackError(f"free parameter {p.name!r}: the same stack leaf {p.path} is freed twice")
            taken.append((i, p.element))
        sizes = [p.size for p in self.params]
        self.offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        rep = lambda a, p: np.tile(a, p.x0.shape[0]) if p.per_sample else a  # noqa: E731
        cat = lambda parts: np.concatenate(parts) if parts else np.zeros(0)  # noqa: E731
        # full coefficient vector (fixed components included) …
        self.full_x0 = cat([p.x0.ravel() for p in self.params])
        fixed = cat([p.fixed.ravel() for p in self.params]).astype(bool)
        # … and the free components the solvers see
        self.free_index = np.nonzero(~fixed)[0]
        idx = self.free_index
        self.size = int(idx.size)
        self.lower = cat([rep(p.lower, p) for p in self.params])[idx]
        self.upper = cat([rep(p.upper, p) for p in self.params])[idx]
        self.scale = cat([rep(p.scale, p) for p in self.params])[idx]
        self.x0 = self.full_x0[idx]
        lo_f, hi_f = np.isfinite(self.lower), np.isfinite(self.upper)
        self.both = np.nonzero(lo_f & hi_f)[0]
        self.low = np.nonzero(lo_f & ~hi_f)[0]
        self.high = np.nonzero(~lo_f & hi_f)[0]
        self.free = np.nonzero(~lo_f & ~hi_f)[0]
        self.names = [self._component(int(j)) for j in idx]
        # which parameter each free component belongs to
        owner = cat([np.full(p.size, i) for i, p in enumerate(self.params)]).astype(int)
        self.owner = owner[idx]
        self.free_count = [int((self.owner == i).sum()) for i in range(len(self.params))]

    def _component(self, j: int) -> str:
        i = int(np.searchsorted(self.offsets, j, side="right") - 1)
        p = self.params[i]
        k = j - self.offsets[i]
        if p.per_sample:
            s, c = divmod(k, p.m)
            return f"{p.name}[sample {s}]" + (f"[{c}]" if p.m > 1 else "")
        return p.name + (f"[{k}]" if p.m > 1 else "")

    # ------------------------------------------------------------- transforms
    def to_physical(self, u):
        """Unconstrained ``u`` → physical ``x`` (module docstring)."""
        lo, hi, s = (jnp.asarray(a, dtype=u.dtype) for a in (self.lower, self.upper, self.scale))
        x = jnp.zeros_like(u)
        b, lw, hg, fr = self.both, self.low, self.high, self.free
        if b.size:
            x = x.at[b].set(lo[b] + (hi[b] - lo[b]) * jnp.reciprocal(1.0 + jnp.exp(-u[b])))
        if lw.size:
            x = x.at[lw].set(lo[lw] + s[lw] * jnp.exp(u[lw]))
        if hg.size:
            x = x.at[hg].set(hi[hg] - s[hg] * jnp.exp(u[hg]))
        if fr.size:
            x = x.at[fr].set(s[fr] * u[fr])
        return x

    def to_unconstrained(self, x) -> np.ndarray:
        """Inverse of :meth:`to_physical` (numpy); values on a bound are nudged inside by
        1e-3 of the range or scale — beyond the 1e-4 within which a solve holds a component on
        its bound (:func:`fitting._fit_functions.hold_on_bounds`), so a start on a bound may leave it."""
        x = np.asarray(x, dtype=float)
        u = np.zeros_like(x)
        lo, hi, s = self.lower, self.upper, self.scale
        b, lw, hg, fr = self.both, self.low, self.high, self.free
        if b.size:
            t = np.clip((x[..., b] - lo[b]) / (hi[b] - lo[b]), _NUDGE, 1 - _NUDGE)
            u[..., b] = np.log(t) - np.log1p(-t)
        if lw.size:
            u[..., lw] = np.log(np.maximum((x[..., lw] - lo[lw]) / s[lw], _NUDGE))
        if hg.size:
            u[..., hg] = np.log(np.maximum((hi[hg] - x[..., hg]) / s[hg], _NUDGE))
        if fr.size:
            u[..., fr] = x[..., fr] / s[fr]
        return u

    # --------------------------------------------------------------- unpacking
    def full(self, x, fill=None):
        """Free components ``(..., P)`` → all coefficients ``(..., F)``; fixed ones take their
        starting value, or ``fill`` if given."""
        base = self.full_x0 if fill is None else np.full(self.full_x0.shape, fill, dtype=float)
        if isinstance(x, np.ndarray):
            out = np.broadcast_to(base, x.shape[:-1] + base.shape).astype(float)
            out[..., self.free_index] = x
            return out
        out = jnp.broadcast_to(jnp.asarray(base, dtype=x.dtype), x.shape[:-1] + base.shape)
        return out.at[..., self.free_index].set(x)

    def split(self, x, fill=None) -> list:
        """Free components ``(..., P)`` → per-parameter coefficient arrays ``(..., m)`` or
        ``(..., samples, m)`` (fixed components: starting value, or ``fill``)."""
        f = self.full(x, fill)
        out = []
        for p, a, b in zip(self.params, self.offsets[:-1], self.offsets[1:]):
            out.append(f[..., a:b].reshape(f.shape[:-1] + p.x0.shape))
        return out

    def values(self, x, fill=None) -> dict:
        """``{name: value}`` in each parameter's public shape (scalars for one-number leaves)."""
        x = np.asarray(x, dtype=float)
        return {p.name: np.asarray(c).reshape(x.shape[:-1] + p.public_shape)
                for p, c in zip(self.params, self.split(x, fill))}

    def inject(self, stack: Stack, coefficients: list, sample=None) -> Stack:
        """Put the parameter values (per sample: row ``sample``, or already sliced when
        ``sample`` is None and the arrays are per-sample rows) into ``stack`` (``equinox.tree_at``)."""
        if not self.params:
            return stack
        leaves = []
        for p, c in zip(self.params, coefficients):
            if p.per_sample and sample is not None:
                c = c[sample]
            leaves.append(p.leaf(c))
        values = []
        if not self._targets:
            return stack
        for lp, taken in self._targets.items():
            if taken[0][1] is None:  # the whole leaf
                values.append(leaves[taken[0][0]])
                continue
            # free elements set, the others as in the stack
            a = jnp.asarray(get_path(stack, lp), dtype=jnp.result_type(float, *(leaves[i] for i, _ in taken)))
            for i, e in taken:
                a = a.at[e].set(leaves[i])
            values.append(a)
        paths = tuple(self._targets)
        return eqx.tree_at(
            lambda st: tuple(get_path(st, path) for path in paths),
            stack,
            tuple(values),
            is_leaf=lambda x: x is None,
        )

    def inject_geometries(self, geometries: Sequence, coefficients: list) -> tuple:
        """The datasets' geometries with the :func:`instrument` parameters put in (one scalar
        each, ``equinox.tree_at``); geometries no parameter names are returned as they are."""
        out = list(geometries)
        # one value per parameter, the same object in every geometry it enters: readings of one
        # instrument at several angles then share one reading (layerstack_jax.shared_readings)
        value = {i: jnp.reshape(coefficients[i], ()) for i in set(self._instrument.values())}
        for (k, field), i in self._instrument.items():
            out[k] = eqx.tree_at(lambda g: getattr(g, field), out[k], value[i])
        return tuple(out)
