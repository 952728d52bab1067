"""Benchmark case definitions, shared by every implementation (peers and ``layerstack_jax``).

Every case is a plain description of a coherent stack made of numpy arrays, so that any
implementation can be fed from it without importing anything heavy:

* ``n``           -- complex refractive indices, shape ``(layers + 2, W)``: row 0 is the
                     ambient (incidence) medium, the last row the exit medium.  Convention
                     ``n + i k`` with ``k >= 0`` for absorption (the ``tmm`` package's).
* ``d``           -- thicknesses of the ``layers`` finite layers in nm, shape ``(layers,)``.
* ``wavelengths`` -- vacuum wavelengths in nm, shape ``(W,)``.
* ``angles``      -- angles of incidence in the ambient medium, radians, shape ``(A,)``.
* ``pols``        -- polarizations, ``("s", "p")``.

Outputs expected from an implementation: ``R`` and ``T`` of shape ``(len(pols), A, W)``.

Gradient benchmarks use the scalar objective :func:`objective` (mean reflectance over both
polarizations, all angles and all wavelengths) differentiated w.r.t. ``d``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

__all__ = [
    "CoherentStack",
    "P1",
    "P1_SEED",
    "CASES",
    "get_case",
    "objective",
    "random_stack",
]


@dataclass(frozen=True)
class CoherentStack:
    """A coherent multilayer and the (angle x wavelength) grid on which it is evaluated."""

    name: str
    n: np.ndarray  # (L + 2, W) complex128
    d: np.ndarray  # (L,) float64, nm
    wavelengths: np.ndarray  # (W,) float64, nm
    angles: np.ndarray  # (A,) float64, rad
    pols: tuple[str, ...] = ("s", "p")
    description: str = ""
    meta: dict = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        n, d = self.n, self.d
        if n.ndim != 2 or n.shape[1] != self.wavelengths.shape[0]:
            raise ValueError(f"n must be (layers+2, W); got {n.shape} for W={self.wavelengths.shape[0]}")
        if d.ndim != 1 or n.shape[0] != d.shape[0] + 2:
            raise ValueError(f"d must be (layers,) with layers = n.shape[0] - 2; got {d.shape} vs {n.shape}")

    @property
    def n_layers(self) -> int:
        return int(self.d.shape[0])

    @property
    def shape(self) -> tuple[int, int, int]:
        """Shape of R and T: (pols, angles, wavelengths)."""
        return (len(self.pols), int(self.angles.shape[0]), int(self.wavelengths.shape[0]))

    @property
    def n_points(self) -> int:
        """Number of (pol, angle, wavelength) evaluations."""
        p, a, w = self.shape
        return p * a * w

    def as_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(n, d, wavelengths, angles)`` as plain numpy arrays (copies)."""
        return (self.n.copy(), self.d.copy(), self.wavelengths.copy(), self.angles.copy())

    def subset(self, angle_idx, wl_idx, suffix: str = "[subset]") -> "CoherentStack":
        """The same stack on a sub-grid (indices into ``angles`` and ``wavelengths``)."""
        angle_idx = np.asarray(angle_idx)
        wl_idx = np.asarray(wl_idx)
        meta = dict(self.meta, parent=self.name, angle_idx=angle_idx.tolist(), wl_idx=wl_idx.tolist())
        return replace(
            self,
            name=self.name + suffix,
            n=self.n[:, wl_idx],
            wavelengths=self.wavelengths[wl_idx],
            angles=self.angles[angle_idx],
            meta=meta,
        )

    def strided_subset(self, n_angles: int, n_wavelengths: int) -> "CoherentStack":
        """Evenly spread sub-grid with (about) ``n_angles`` x ``n_wavelengths`` points, ends included."""
        a_idx = _spread(self.angles.shape[0], n_angles)
        w_idx = _spread(self.wavelengths.shape[0], n_wavelengths)
        return self.subset(a_idx, w_idx, suffix=f"[{len(a_idx)}x{len(w_idx)} subset]")


def _spread(total: int, k: int) -> np.ndarray:
    k = max(1, min(int(k), total))
    return np.unique(np.round(np.linspace(0, total - 1, k)).astype(int))


# --------------------------------------------------------------------------------------
# P1: 10-layer TiO2/SiO2-like quarter-wave-ish stack, 64 angles x 1000 wavelengths, s and p.
# --------------------------------------------------------------------------------------

P1_SEED = 20240601
P1_N_HIGH = 2.35  # TiO2-like, dispersionless
P1_N_LOW = 1.46  # SiO2-like, dispersionless
P1_N_AMBIENT = 1.0
P1_N_EXIT = 1.52  # glass


def P1() -> CoherentStack:
    """Case P1 (float64).

    10 coherent layers alternating n = 2.35 and n = 1.46 (first layer, next to the ambient, is
    the high-index one), thicknesses drawn once with ``numpy.random.default_rng(P1_SEED)``
    uniformly in [50, 200] nm; ambient air n = 1, exit glass n = 1.52; 1000 wavelengths
    linearly spaced over 400-1000 nm; 64 angles linearly spaced over 0-80 degrees; s and p.
    """
    rng = np.random.default_rng(P1_SEED)
    d = rng.uniform(50.0, 200.0, size=10).astype(np.float64)
    wavelengths = np.linspace(400.0, 1000.0, 1000, dtype=np.float64)
    angles = np.deg2rad(np.linspace(0.0, 80.0, 64, dtype=np.float64))
    layer_n = np.array([P1_N_HIGH if i % 2 == 0 else P1_N_LOW for i in range(10)])
    col = np.concatenate([[P1_N_AMBIENT], layer_n, [P1_N_EXIT]]).astype(np.complex128)
    n = np.repeat(col[:, None], wavelengths.shape[0], axis=1)
    return CoherentStack(
        name="P1",
        n=n,
        d=d,
        wavelengths=wavelengths,
        angles=angles,
        pols=("s", "p"),
        description=(
            "10 coherent layers alternating n=2.35/1.46 (d ~ U[50,200] nm, seed "
            f"{P1_SEED}), air | stack | glass n=1.52, 1000 wl 400-1000 nm, 64 angles 0-80 deg, s+p, float64"
        ),
    )


CASES = {"P1": P1}


def get_case(name: str) -> CoherentStack:
    try:
        return CASES[name]()
    except KeyError:
        raise KeyError(f"unknown case {name!r}; known: {sorted(CASES)}") from None


def objective(R: np.ndarray) -> float:
    """Scalar objective used by the gradient benchmarks: mean of R over (pols, angles, wavelengths).

    Implementations compute it in their own framework (``R.mean()``); this is the numpy form.
    """
    return float(np.mean(R))


def random_stack(
    seed: int = 0,
    n_layers: int = 6,
    n_wavelengths: int = 9,
    n_angles: int = 7,
    absorbing: bool = True,
) -> CoherentStack:
    """Small random dispersive (and by default absorbing) stack used to validate peers.

    Ambient n = 1 and exit n = 1.52 are real (required by several peers, and by the usual
    definition of T); inner layers get a Cauchy-like n(lambda) in [1.3, 2.6] and, when
    ``absorbing``, an extinction k(lambda) in [0, 0.15].
    """
    rng = np.random.default_rng(seed)
    wl = np.linspace(380.0, 1100.0, n_wavelengths)
    a = rng.uniform(1.3, 2.4, n_layers)
    b = rng.uniform(0.0, 2.0e4, n_layers)  # nm^2
    n_real = a[:, None] + b[:, None] / wl[None, :] ** 2
    if absorbing:
        k0 = rng.uniform(0.0, 0.15, n_layers)
        k = k0[:, None] * (wl.min() / wl[None, :])
    else:
        k = np.zeros_like(n_real)
    inner = n_real + 1j * k
    n = np.concatenate([np.ones((1, wl.size)), inner, np.full((1, wl.size), 1.52)], axis=0).astype(np.complex128)
    d = rng.uniform(10.0, 300.0, n_layers)
    angles = np.deg2rad(np.linspace(0.0, 80.0, n_angles))
    return CoherentStack(
        name=f"random(seed={seed})",
        n=n,
        d=d,
        wavelengths=wl,
        angles=angles,
        description=f"random {n_layers}-layer dispersive{' absorbing' if absorbing else ''} stack",
    )
