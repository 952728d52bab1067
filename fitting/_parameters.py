r"""Free parameters of a stack: where they sit in the :class:`~layerstack_jax.Stack` pytree,
their bounds, their spectral basis, and how they are packed into one flat vector.

A :class:`Parameter` names one numeric leaf of the stack by its *path*, e.g.
``("layers", "varnish", "thickness")`` or ``("exit", "reflectance")``; layers may be given by
position or by name. Its value is a vector of *coefficients* :math:`c` (one number for a
scalar leaf). A spectral leaf (α(λ), ρg(λ), n(λ)) is :math:`v = B c` on the model wavelength grid,
with ``B`` of shape ``(wl, m)``: the identity (``basis="free"``: one free value per wavelength),
a clamped B-spline basis of ``m`` functions (``basis=m``, :func:`bspline_basis`) or any matrix.
B-splines are non-negative and sum to one, so bounds on the coefficients bound the spectrum:
:math:`c \ge 0 \Rightarrow \alpha(\lambda) \ge 0`, :math:`0 \le c \le 1 \Rightarrow 0 \le \rho_g(\lambda) \le 1`.

A path may end with an element index into a 1-D array leaf — one term of a Sellmeier ``B``
(``("layers", "glass", "index", "B", 0)``), one oscillator of a list — so that single entries
are fitted while the others stay as in the stack (:class:`Layout` sets them with ``.at[].set``).

A path rooted at ``"datasets"`` names a number of the instrument instead of the stack — a field
of a dataset's geometry such as an ellipsometer's ``angle_offset_deg``, ``bandwidth_nm`` or
``thickness_spread`` (:class:`layerstack_jax.Ellipsometric`): ``("datasets", 0,
"angle_offset_deg")`` for dataset 0, ``("datasets", (0, 1, 2), "angle_offset_deg")`` for one value
shared by datasets 0–2, ``("datasets", "all", "angle_offset_deg")`` for every dataset whose
geometry has that field (one offset for all angles of a multi-angle fit); built by
:func:`instrument`. The :class:`~fitting.Objective` puts the value into each named geometry
(:meth:`Layout.inject_geometries`) before it measures; such a parameter is one scalar shared by
all samples.

A parameter is *shared* by all samples of a fit or *per sample* (``per_sample=True``: one
coefficient vector per sample, e.g. the thicknesses of a calibration series).

How a parameter is found in a stack and packed with the others into one vector for the solvers:
:mod:`fitting._layout`.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Optional, Sequence, Union

import numpy as np
from jax.typing import ArrayLike

from layerstack_jax import LayerstackError, RealLike

__all__ = [
    "Parameter",
    "thickness",
    "alpha",
    "rho_g",
    "index_n",
    "dispersion",
    "instrument",
    "bspline_basis",
    "is_instrument_path",
    "DEFAULT_BOUNDS",
]

LayerRef = Union[int, str]
_KINDS = ("thickness", "alpha", "rho_g", "n", "coefficient", "other")
# default bounds by kind (PHYSICS conventions: thickness >= 0, 0 <= rho_g <= 1, alpha >= 0, n >= 1)
DEFAULT_BOUNDS = {
    "thickness": (0.0, math.inf),
    "alpha": (0.0, math.inf),
    "rho_g": (0.0, 1.0),
    "n": (1.0, math.inf),
    "coefficient": (-math.inf, math.inf),
    "other": (-math.inf, math.inf),
}


@dataclasses.dataclass(frozen=True, eq=False)
class Parameter:
    """One free parameter: a numeric leaf of the stack, its bounds and its spectral basis.

    Attributes:
        name: label in reports (default: built from the path).
        path: location of the leaf, e.g. ``("layers", 0, "thickness")``, ``("layers", "varnish",
            "alpha")``, ``("exit", "reflectance")``, ``("layers", 1, "index", "A")``; a final
            integer addresses one element of an array leaf (``("layers", 1, "index", "B", 0)``:
            the first Sellmeier term) or, before it, an entry of a tuple (``("layers", 0,
            "index", "materials", 0, "A")``: a constituent of an effective medium).
        kind: ``thickness`` (nm), ``alpha`` (1/nm), ``rho_g``, ``n``, ``coefficient`` or
            ``other``; decides the default bounds.
        value: starting value (coefficients), or None to take it from the stack. Scalar,
            ``(m,)``, or for a per-sample parameter ``(samples,)`` / ``(samples, m)``.
        lower, upper: bounds on the coefficients (scalar or ``(m,)``); None: the kind's default.
        basis: None (the leaf itself is the value: scalar or a vector of coefficients such as
            Sellmeier B), ``"free"`` (one value per model wavelength), an int m (clamped cubic
            B-splines with m functions over the model grid) or a ``(wl, m)`` matrix.
        per_sample: one value per sample instead of one shared by all samples.
        smoothness: weight of a second-difference penalty on the spectrum ``B c`` (adds
            residuals :math:`\\sqrt{w}\\,\\Delta^2 v`); 0 for none.
        scale: typical magnitude (default: from the starting value); conditions the solvers.
        fixed: optional boolean mask shaped like the value (e.g. ``[True, False, False]`` for
            a per-sample thickness whose first sample is known): those components keep their
            starting value and are not fitted.
    """

    path: tuple
    kind: str = "other"
    name: str = ""
    value: Optional[RealLike] = None
    lower: Optional[RealLike] = None
    upper: Optional[RealLike] = None
    basis: Union[None, str, int, RealLike] = None
    per_sample: bool = False
    smoothness: float = 0.0
    scale: Optional[RealLike] = None
    fixed: Optional[ArrayLike] = None

    def __post_init__(self):
        if not isinstance(self.path, tuple) or not self.path:
            raise LayerstackError(f"Parameter.path must be a non-empty tuple, got {self.path!r}")
        if self.kind not in _KINDS:
            raise LayerstackError(f"Parameter {self.label}: kind must be one of {_KINDS}, got {self.kind!r}")
        if not (isinstance(self.smoothness, (int, float)) and self.smoothness >= 0):
            raise LayerstackError(f"Parameter {self.label}: smoothness must be a number >= 0, got {self.smoothness!r}")
        if not (self.basis is None or isinstance(self.basis, (str, int, np.ndarray)) or hasattr(self.basis, "shape")):
            raise LayerstackError(f"Parameter {self.label}: basis must be None, 'free', an int or a (wl, m) matrix")
        if isinstance(self.basis, str) and self.basis != "free":
            raise LayerstackError(f"Parameter {self.label}: basis must be None, 'free', an int or a matrix, got {self.basis!r}")

    @property
    def label(self) -> str:
        if self.name:
            return self.name
        parts = [str(p) for p in self.path if p not in ("layers", "index")]
        return ".".join(parts)


def _layer_path(layer: LayerRef, *rest) -> tuple:
    if layer == "ambient":  # the ambient is a material itself, not a layer holding one
        return ("ambient", *(r for r in rest if r != "index"))
    if layer == "exit":
        return ("exit", *rest)
    return ("layers", layer, *rest)


def thickness(layer: LayerRef, *, value=None, lower=None, upper=None, per_sample=False, name="", scale=None,
              fixed=None) -> Parameter:
    """Thickness (nm, default bounds [0, ∞)) of a layer given by position or name: a scalar, or
    ``(samples,)`` with ``per_sample=True``."""
    return Parameter(_layer_path(layer, "thickness"), "thickness", name or f"thickness[{layer}]", value, lower, upper,
                     None, per_sample, 0.0, scale, fixed)


def alpha(layer: LayerRef, *, basis=None, value=None, lower=None, upper=None, per_sample=False, smoothness=0.0,
          name="", scale=None) -> Parameter:
    """Absorption coefficient α (1/nm, default bounds [0, ∞)) of an incoherent layer: a scalar
    (``basis=None``), per wavelength (``"free"``) or on a basis (int m or matrix)."""
    return Parameter(_layer_path(layer, "alpha"), "alpha", name or f"alpha[{layer}]", value, lower, upper, basis,
                     per_sample, smoothness, scale)


def rho_g(*, basis=None, value=None, lower=None, upper=None, per_sample=False, smoothness=0.0, name="rho_g",
          scale=None) -> Parameter:
    """Intrinsic reflectance ρg of the Lambertian background, a dimensionless fraction (default
    bounds [0, 1]): a scalar (``basis=None``), per wavelength (``"free"``, shape ``(wl,)``) or
    on a basis (int m or ``(wl, m)`` matrix: m coefficients); ``per_sample`` adds a leading
    ``(samples,)`` axis."""
    return Parameter(("exit", "reflectance"), "rho_g", name, value, lower, upper, basis, per_sample, smoothness, scale)


def index_n(medium: LayerRef, *, basis=None, value=None, lower=None, upper=None, per_sample=False, smoothness=0.0,
            name="", scale=None) -> Parameter:
    """Real index n (dimensionless, default bounds [1, ∞)) of a medium whose material is an
    :class:`~layerstack_jax.Index`: a layer (position or name), ``"ambient"`` or ``"exit"``. A
    scalar (``basis=None``), per wavelength (``"free"``, shape ``(wl,)``) or on a basis (int m or
    ``(wl, m)`` matrix); ``per_sample`` adds a leading ``(samples,)`` axis."""
    return Parameter(_layer_path(medium, "index", "n"), "n", name or f"n[{medium}]", value, lower, upper, basis,
                     per_sample, smoothness, scale)


def dispersion(medium: LayerRef, coefficient: str, *, value=None, lower=None, upper=None, per_sample=False, name="",
               scale=None) -> Parameter:
    """A coefficient of a :class:`~layerstack_jax.Cauchy` (``A``, ``B``, ``C``, ``k``) or
    :class:`~layerstack_jax.Sellmeier` (``B``, ``C`` — vectors —, ``k``) dispersion (λ in µm).

    Units are the material's: Cauchy A and k dimensionless, B in µm², C in µm⁴; Sellmeier B
    dimensionless, C in µm². The value is a scalar, or ``(term,)`` for Sellmeier B and C;
    ``per_sample`` adds a leading ``(samples,)`` axis. One Sellmeier term alone: a
    :class:`Parameter` whose path ends with its index, ``Parameter(("layers", "glass", "index",
    "B", 0), name="B1")`` (module docstring)."""
    kind = "n" if coefficient == "A" else "coefficient"
    lo = lower if lower is not None else (0.0 if coefficient == "k" else None)
    return Parameter(_layer_path(medium, "index", coefficient), kind, name or f"{coefficient}[{medium}]", value, lo,
                     upper, None, per_sample, 0.0, scale)


def instrument(field: str, datasets: Union[int, Sequence[int], str] = "all", *, value=None, lower=None, upper=None,
               name: str = "", scale=None) -> Parameter:
    """A number of the instrument: field ``field`` of the geometry of one or several datasets of
    the fit, one scalar shared by all of them (module docstring).

    ``field``: e.g. ``"angle_offset_deg"`` (degrees), ``"bandwidth_nm"`` (FWHM, nm; give
    ``lower=0``) or ``"thickness_spread"`` (relative σ; give ``lower=0`` and an ``upper`` below
    :math:`1/x_K`, 0.127 with the default 21 nodes: beyond it a node thickness is negative) of a
    :class:`layerstack_jax.Ellipsometric`. ``datasets``: an index, a sequence of indices
    (one value for all of them, e.g. one angle offset for the datasets of three angles) or
    ``"all"`` (every dataset whose geometry has the field). ``value``: start (default: the
    geometry's value, which must then agree over the datasets). Start a spread or bandwidth above
    0: their derivatives vanish at 0 (the average is even in them)."""
    if isinstance(datasets, str):
        if datasets != "all":
            raise LayerstackError(f"fitting.instrument({field!r}): datasets must be an index, indices or 'all', "
                                  f"got {datasets!r}")
        where = "all"
    elif isinstance(datasets, (int, np.integer)) and not isinstance(datasets, bool):
        where = int(datasets)
    else:
        where = tuple(int(i) for i in datasets)
    return Parameter(("datasets", where, field), "other", name or field, value, lower, upper, None, False, 0.0, scale)


def is_instrument_path(path: tuple) -> bool:
    """True for a path into the datasets' geometries (:func:`instrument`), not into the stack."""
    return bool(path) and path[0] == "datasets"


# --------------------------------------------------------------------------- basis
def bspline_basis(wavelength_nm, n_coefficients: int, degree: int = 3) -> np.ndarray:
    """Clamped B-spline basis on uniform knots spanning the grid, ``(wl, n_coefficients)``.

    Cox–de Boor recursion in numpy (built once, applied as a matrix in jnp). Columns are
    non-negative and each row sums to one (partition of unity). The degree is lowered to
    ``n_coefficients − 1`` when fewer functions than ``degree + 1`` are asked for.
    """
    x = np.asarray(wavelength_nm, dtype=float)
    m = int(n_coefficients)
    if x.ndim != 1 or x.size < 2 or np.any(np.diff(x) <= 0):
        raise LayerstackError("bspline_basis: wavelength_nm must be a strictly increasing 1-D grid of >= 2 points")
    if m < 1 or m > x.size:
        raise LayerstackError(f"bspline_basis: n_coefficients must lie in [1, {x.size}], got {n_coefficients}")
    k = min(int(degree), m - 1)
    inner = np.linspace(x[0], x[-1], m - k + 1)
    t = np.concatenate([np.full(k, x[0]), inner, np.full(k, x[-1])])
    # degree 0
    B = np.zeros((x.size, t.size - 1))
    for j in range(t.size - 1):
        B[:, j] = (t[j] <= x) & (x < t[j + 1])
    last = np.nonzero(t[:-1] < t[1:])[0][-1]
    B[x == x[-1], :] = 0.0
    B[x == x[-1], last] = 1.0  # the right end belongs to the last non-empty interval
    for d in range(1, k + 1):
        nxt = np.zeros((x.size, t.size - 1 - d))
        for j in range(t.size - 1 - d):
            a = t[j + d] - t[j]
            b = t[j + d + 1] - t[j + 1]
            left = (x - t[j]) / a * B[:, j] if a > 0 else 0.0
            right = (t[j + d + 1] - x) / b * B[:, j + 1] if b > 0 else 0.0
            nxt[:, j] = left + right
        B = nxt
    return B
