"""Adapters for peer implementations of the coherent transfer-matrix method.

Every peer is wrapped behind the same interface::

    compute(peer, n, d, wavelengths, angles, pol) -> PeerResult(R, T, status)

* ``n``           complex indices, shape ``(layers + 2, W)`` (or ``(layers + 2,)`` for
                  dispersionless media), ambient first, exit medium last, ``n + ik``;
* ``d``           thicknesses of the finite layers in nm, ``(layers,)``;
* ``wavelengths`` vacuum wavelengths in nm, ``(W,)``;
* ``angles``      angles of incidence in radians, ``(A,)``;
* ``pol``         ``"s"`` or ``"p"``.

``R`` and ``T`` are float64 numpy arrays of shape ``(A, W)``; ``status`` is ``"ok"`` or
starts with ``"missing:"`` (peer not importable) or ``"failed:"`` (it raised, or gave wrong
answers), followed by the reason. A peer that cannot run is never silently dropped.

For benchmarking, :class:`Peer` objects additionally build closures on pre-converted
native inputs (torch tensors, jax arrays) so that conversion is not timed:
``Peer.build_forward(stack)`` and ``Peer.build_value_and_grad(stack)``.

Peers (none is imported when this module is imported):

=================  ==========================================================================
``tmm``            Byrnes' reference, ``tmm.coh_tmm`` in a Python loop (one point per call).
``tmm-fast``       PyTorch, vectorized over stacks x angles x wavelengths; autograd.
``tmm-faster``     C++/OpenMP core (``tmm_faster.calc_coherent``), both polarizations per call.
``jaxlayerlumos``  JAX (``stackrt_n_k``), eager: its entry point is not jittable.
``tmmax``          JAX (``vectorized_coh_tmm``); complex64 hard-coded, see its status.
=================  ==========================================================================
"""

from __future__ import annotations

import importlib
import importlib.metadata as _md
from dataclasses import dataclass, field
from typing import Any, Callable, NamedTuple

import numpy as np

from .cases import CoherentStack, random_stack

__all__ = [
    "PeerResult",
    "Peer",
    "Built",
    "PEERS",
    "ADAPTERS",
    "compute",
    "reference",
    "validate",
    "validated",
    "peer_version",
]

C_LIGHT = 299792458.0  # m/s
VALIDATION_TOL = 1e-10


class PeerResult(NamedTuple):
    R: np.ndarray | None  # (A, W)
    T: np.ndarray | None  # (A, W)
    status: str  # "ok" | "missing: ..." | "failed: ..."


@dataclass
class Built:
    """A ready-to-time closure. ``fn(*args)`` runs the work; ``to_numpy(out)`` converts.

    forward:         ``to_numpy(out) -> (R, T)``, each ``(P, A, W)`` float64.
    value_and_grad:  ``to_numpy(out) -> (value, grad)`` with ``grad`` of shape ``(layers,)``.
    """

    fn: Callable
    args: tuple = ()
    to_numpy: Callable[[Any], Any] = lambda out: out
    notes: list[str] = field(default_factory=list)
    # forward on an arbitrary stack, for gradient checks by finite differences (optional)
    objective_fn: Callable[[np.ndarray], float] | None = None


def _as_n2d(n, n_wl: int) -> np.ndarray:
    n = np.asarray(n, dtype=np.complex128)
    if n.ndim == 1:
        n = np.repeat(n[:, None], n_wl, axis=1)
    if n.ndim != 2 or n.shape[1] != n_wl:
        raise ValueError(f"n must be (layers+2,) or (layers+2, W={n_wl}); got {n.shape}")
    return n


def _stack_from_arrays(n, d, wavelengths, angles, pols=("s", "p")) -> CoherentStack:
    wl = np.atleast_1d(np.asarray(wavelengths, dtype=np.float64))
    return CoherentStack(
        name="adhoc",
        n=_as_n2d(n, wl.size),
        d=np.atleast_1d(np.asarray(d, dtype=np.float64)),
        wavelengths=wl,
        angles=np.atleast_1d(np.asarray(angles, dtype=np.float64)),
        pols=tuple(pols),
    )


def peer_version(dist: str) -> str | None:
    try:
        return _md.version(dist)
    except _md.PackageNotFoundError:
        return None


def _short_exc(e: BaseException, limit: int = 300) -> str:
    msg = f"{type(e).__name__}: {e}".strip().replace("\n", " ")
    return msg if len(msg) <= limit else msg[: limit - 3] + "..."


class Peer:
    """Base class: subclasses implement ``_import`` and ``build_forward``."""

    name: str = ""
    dist: str = ""  # pip distribution name
    description: str = ""
    supports_grad: bool = False

    def version(self) -> str | None:
        return peer_version(self.dist)

    def _import(self):  # -> module
        raise NotImplementedError

    def available(self) -> tuple[bool, str]:
        """(True, "ok") or (False, "missing: <reason>")."""
        try:
            self._import()
        except Exception as e:  # ImportError, or anything raised at import
            hint = f" (pip install {self.dist})" if isinstance(e, ImportError) else ""
            return False, f"missing: {_short_exc(e)}{hint}"
        return True, "ok"

    def build_forward(self, stack: CoherentStack) -> Built:
        raise NotImplementedError

    def build_value_and_grad(self, stack: CoherentStack) -> Built:
        raise NotImplementedError(f"{self.name}: gradients not supported by this adapter")

    # ----- the simple adapter ------------------------------------------------------
    def compute(self, n, d, wavelengths, angles, pol: str) -> PeerResult:
        if pol not in ("s", "p"):
            return PeerResult(None, None, f"failed: pol must be 's' or 'p', got {pol!r}")
        ok, why = self.available()
        if not ok:
            return PeerResult(None, None, why)
        try:
            stack = _stack_from_arrays(n, d, wavelengths, angles, pols=(pol,))
            b = self.build_forward(stack)
            R, T = b.to_numpy(b.fn(*b.args))
            R, T = np.asarray(R, dtype=np.float64)[0], np.asarray(T, dtype=np.float64)[0]
        except Exception as e:
            return PeerResult(None, None, f"failed: {_short_exc(e)}")
        if R.shape != (stack.angles.size, stack.wavelengths.size) or not (np.all(np.isfinite(R)) and np.all(np.isfinite(T))):
            return PeerResult(R, T, f"failed: bad output (shape {R.shape}, finite={bool(np.all(np.isfinite(R)))})")
        return PeerResult(R, T, "ok")

    def compute_stack(self, stack: CoherentStack) -> tuple[np.ndarray | None, np.ndarray | None, str]:
        """Both polarizations of ``stack`` at once: R, T of shape (P, A, W), status."""
        ok, why = self.available()
        if not ok:
            return None, None, why
        try:
            b = self.build_forward(stack)
            R, T = b.to_numpy(b.fn(*b.args))
            return np.asarray(R, dtype=np.float64), np.asarray(T, dtype=np.float64), "ok"
        except Exception as e:
            return None, None, f"failed: {_short_exc(e)}"


# --------------------------------------------------------------------------------------
# tmm (reference)
# --------------------------------------------------------------------------------------


class TmmPeer(Peer):
    name = "tmm"
    dist = "tmm"
    description = "Byrnes tmm.coh_tmm, Python double loop over angles x wavelengths (reference)"

    def _import(self):
        return importlib.import_module("tmm")

    def build_forward(self, stack: CoherentStack) -> Built:
        tmm = self._import()
        coh_tmm = tmm.coh_tmm
        d_list = [np.inf] + [float(x) for x in stack.d] + [np.inf]
        n_cols = [stack.n[:, w].copy() for w in range(stack.wavelengths.size)]
        lams = [float(x) for x in stack.wavelengths]
        angles = [float(x) for x in stack.angles]
        pols = stack.pols
        shape = stack.shape

        def run():
            R = np.empty(shape)
            T = np.empty(shape)
            for ip, pol in enumerate(pols):
                for ia, th in enumerate(angles):
                    for iw, lam in enumerate(lams):
                        out = coh_tmm(pol, n_cols[iw], d_list, th, lam)
                        R[ip, ia, iw] = out["R"]
                        T[ip, ia, iw] = out["T"]
            return R, T

        return Built(fn=run, to_numpy=lambda out: out, notes=["one tmm.coh_tmm call per (pol, angle, wavelength)"])


# --------------------------------------------------------------------------------------
# tmm-fast (PyTorch)
# --------------------------------------------------------------------------------------


class TmmFastPeer(Peer):
    name = "tmm-fast"
    dist = "tmm-fast"
    description = "tmm_fast.coh_tmm (PyTorch, CPU), vectorized over angles x wavelengths; autograd"
    supports_grad = True

    def _import(self):
        importlib.import_module("torch")
        return importlib.import_module("tmm_fast")

    @staticmethod
    def _threads() -> int:
        import torch

        from ._harness import cpu_count

        n = cpu_count()
        if torch.get_num_threads() != n:
            torch.set_num_threads(n)
        return torch.get_num_threads()

    def _inputs(self, stack: CoherentStack):
        import torch

        N = torch.as_tensor(stack.n[None, :, :].copy(), dtype=torch.complex128)  # (1, L+2, W)
        D = torch.as_tensor(np.concatenate([[np.inf], stack.d, [np.inf]])[None, :], dtype=torch.float64)  # (1, L+2)
        Theta = torch.as_tensor(stack.angles, dtype=torch.float64)  # (A,)
        lam = torch.as_tensor(stack.wavelengths, dtype=torch.float64)  # (W,), same unit (nm) as D
        return N, D, Theta, lam

    def build_forward(self, stack: CoherentStack) -> Built:
        tmm_fast = self._import()
        import torch

        threads = self._threads()
        N, D, Theta, lam = self._inputs(stack)
        pols = stack.pols

        def run(N, D, Theta, lam):
            Rs, Ts = [], []
            with torch.no_grad():
                for pol in pols:
                    out = tmm_fast.coh_tmm(pol, N, D, Theta, lam, device="cpu")
                    Rs.append(out["R"][0])
                    Ts.append(out["T"][0])
            return torch.stack(Rs), torch.stack(Ts)

        def to_numpy(out):
            R, T = out
            assert R.dtype == torch.float64 and T.dtype == torch.float64, (R.dtype, T.dtype)
            return R.numpy(), T.numpy()

        notes = [f"torch {torch.__version__}, {threads} threads, complex128 internally", "one coh_tmm call per polarization"]
        return Built(fn=run, args=(N, D, Theta, lam), to_numpy=to_numpy, notes=notes)

    def build_value_and_grad(self, stack: CoherentStack) -> Built:
        tmm_fast = self._import()
        import torch

        threads = self._threads()
        N, _, Theta, lam = self._inputs(stack)
        pols = stack.pols
        inf = torch.tensor([np.inf], dtype=torch.float64)

        def objective_and_grad(d_np):
            d = torch.tensor(d_np, dtype=torch.float64, requires_grad=True)
            D = torch.cat([inf, d, inf])[None, :]
            R = torch.stack([tmm_fast.coh_tmm(pol, N, D, Theta, lam, device="cpu")["R"][0] for pol in pols])
            loss = R.mean()
            loss.backward()
            return loss.detach(), d.grad

        def objective_only(d_np):
            with torch.no_grad():
                D = torch.as_tensor(np.concatenate([[np.inf], d_np, [np.inf]])[None, :], dtype=torch.float64)
                R = torch.stack([tmm_fast.coh_tmm(pol, N, D, Theta, lam, device="cpu")["R"][0] for pol in pols])
                return float(R.mean())

        d0 = np.asarray(stack.d, dtype=np.float64).copy()
        notes = [f"torch {torch.__version__} autograd, {threads} threads; objective mean(R) over pols x angles x wavelengths"]
        return Built(
            fn=objective_and_grad,
            args=(d0,),
            to_numpy=lambda out: (float(out[0]), out[1].numpy().copy()),
            notes=notes,
            objective_fn=objective_only,
        )


# --------------------------------------------------------------------------------------
# tmm-faster (C++ / OpenMP)
# --------------------------------------------------------------------------------------


class TmmFasterPeer(Peer):
    name = "tmm-faster"
    dist = "tmm-faster"
    description = "tmm_faster.calc_coherent (C++ core, OpenMP), s and p in one call"

    def _import(self):
        return importlib.import_module("tmm_faster")

    def build_forward(self, stack: CoherentStack) -> Built:
        tf = self._import()
        n_matrix = np.ascontiguousarray(stack.n.T)  # (W, L+2)
        d_list = [0.0] + [float(x) for x in stack.d] + [0.0]  # nm, edges ignored
        angles_deg = np.rad2deg(stack.angles).tolist()
        wl = stack.wavelengths.tolist()
        pols = stack.pols
        core = tf.core()

        def run():
            return core.calc_coherent(n_matrix, d_list, angles_deg, wl)

        def to_numpy(out):
            # outputs are (W, A)
            R = np.stack([np.asarray(out[f"R_{p}"], dtype=np.float64).T for p in pols])
            T = np.stack([np.asarray(out[f"T_{p}"], dtype=np.float64).T for p in pols])
            return R, T

        return Built(fn=run, to_numpy=to_numpy, notes=["C++/OpenMP; always computes both s and p (and averages)"])


# --------------------------------------------------------------------------------------
# jaxlayerlumos (JAX, eager)
# --------------------------------------------------------------------------------------


class JaxLayerLumosPeer(Peer):
    name = "jaxlayerlumos"
    dist = "jaxlayerlumos"
    description = "jaxlayerlumos.stackrt_n_k (JAX; vmapped but not jittable, runs eagerly)"
    supports_grad = True

    def _import(self):
        # NB: importing jaxlayerlumos turns on jax_enable_x64 globally.
        return importlib.import_module("jaxlayerlumos")

    def _inputs(self, stack: CoherentStack):
        import jax.numpy as jnp

        nk = jnp.asarray(stack.n.T)  # (W, L+2)
        f = jnp.asarray(C_LIGHT / (stack.wavelengths * 1e-9))  # Hz
        th = jnp.asarray(np.rad2deg(stack.angles))  # degrees
        return nk, f, th

    @staticmethod
    def _d_m(d_nm):
        import jax.numpy as jnp

        return jnp.concatenate([jnp.zeros(1), jnp.asarray(d_nm) * 1e-9, jnp.zeros(1)])  # metres, edges 0

    def _select(self, out, pols):
        R_TE, T_TE, R_TM, T_TM = out
        Rm = {"s": R_TE, "p": R_TM}
        Tm = {"s": T_TE, "p": T_TM}
        return [Rm[p] for p in pols], [Tm[p] for p in pols]

    def build_forward(self, stack: CoherentStack) -> Built:
        jll = self._import()
        import jax
        import jax.numpy as jnp

        nk, f, th = self._inputs(stack)
        d_m = self._d_m(stack.d)
        pols = stack.pols

        def run(nk, d_m, f, th):
            out = jll.stackrt_n_k(nk, d_m, f, th)  # each (A, W)
            Rs, Ts = self._select(out, pols)
            return jnp.stack(Rs), jnp.stack(Ts)

        notes = [f"eager JAX (stackrt_n_k asserts on values, so jax.jit fails), x64={jax.config.jax_enable_x64}",
                 "thicknesses in m, frequencies in Hz (f = c/lambda); s and p in one call"]
        return Built(fn=run, args=(nk, d_m, f, th), to_numpy=lambda o: (np.asarray(o[0]), np.asarray(o[1])), notes=notes)

    def build_value_and_grad(self, stack: CoherentStack) -> Built:
        jll = self._import()
        import jax
        import jax.numpy as jnp

        nk, f, th = self._inputs(stack)
        pols = stack.pols

        def objective(d_nm):
            Rs, _ = self._select(jll.stackrt_n_k(nk, self._d_m(d_nm), f, th), pols)
            return jnp.mean(jnp.stack(Rs))

        vg = jax.value_and_grad(objective)
        d0 = jnp.asarray(stack.d)
        notes = ["jax.value_and_grad, eager (not jittable); objective mean(R) over pols x angles x wavelengths"]
        return Built(
            fn=vg,
            args=(d0,),
            to_numpy=lambda o: (float(o[0]), np.asarray(o[1])),
            notes=notes,
            objective_fn=lambda d_np: float(objective(jnp.asarray(d_np))),
        )


# --------------------------------------------------------------------------------------
# tmmax (JAX)
# --------------------------------------------------------------------------------------


class TmmaxPeer(Peer):
    name = "tmmax"
    dist = "tmmax"
    description = "tmmax.tmm.vectorized_coh_tmm (JAX, jitted); complex64 hard-coded"

    def _import(self):
        return importlib.import_module("tmmax.tmm")

    def build_forward(self, stack: CoherentStack) -> Built:
        tm = self._import()
        import jax
        import jax.numpy as jnp

        # tmmax interpolates n,k from per-material tables: give every layer its own "material"
        # tabulated exactly on the evaluation wavelengths (interpolation is then exact).
        L2, W = stack.n.shape
        wl = stack.wavelengths
        if W == 1:  # jnp.interp needs >= 2 nodes
            wl_tab = np.array([wl[0] * (1 - 1e-9), wl[0] * (1 + 1e-9)])
            n_tab = np.repeat(stack.n, 2, axis=1)
        else:
            wl_tab, n_tab = wl, stack.n
        data = np.empty((L2, 3, wl_tab.size))
        data[:, 0, :] = wl_tab[None, :]
        data[:, 1, :] = n_tab.real
        data[:, 2, :] = n_tab.imag
        # tmmax hard-codes complex64 (create_nk_list, scan carry); with jax_enable_x64 on, its scan
        # raises a dtype mismatch, so run it with x64 off -> float32 results.
        x64_off = getattr(jax, "enable_x64", None)
        pols = stack.pols

        def make_args():
            return (jnp.asarray(data), jnp.arange(L2), jnp.asarray(stack.d), jnp.asarray(wl), jnp.asarray(stack.angles))

        def run(*a):
            Rs, Ts = [], []
            for p in pols:
                R, T = tm.vectorized_coh_tmm(*a, jnp.array([p == "p"]))
                Rs.append(R)
                Ts.append(T)
            return jnp.stack(Rs), jnp.stack(Ts)

        if x64_off is not None and jax.config.jax_enable_x64:
            def run_f32(*a):
                with x64_off(False):
                    return jax.block_until_ready(run(*a))

            with x64_off(False):
                args = make_args()
            fn = run_f32
        else:
            args = make_args()
            fn = run
        notes = ["float32 only (complex64 hard-coded); each layer passed as its own tabulated material"]
        return Built(fn=fn, args=args, to_numpy=lambda o: (np.asarray(o[0], np.float64), np.asarray(o[1], np.float64)), notes=notes)


# --------------------------------------------------------------------------------------
# registry, reference, validation
# --------------------------------------------------------------------------------------

PEERS: dict[str, Peer] = {p.name: p for p in (TmmPeer(), TmmFastPeer(), TmmFasterPeer(), JaxLayerLumosPeer(), TmmaxPeer())}


_VALIDATED: dict[str, "Validation"] = {}


def validated(peer: str) -> "Validation":
    """:func:`validate` once per process (cached)."""
    if peer not in _VALIDATED:
        _VALIDATED[peer] = validate(peer)
    return _VALIDATED[peer]


def compute(peer: str, n, d, wavelengths, angles, pol: str, check: bool = True) -> PeerResult:
    """R, T of shape (A, W) and a status string for one peer and one polarization.

    With ``check`` (default) the peer is first validated against tmm (once per process, see
    :func:`validate`); a peer that disagrees still returns its arrays, but with status
    ``"failed: disagrees with tmm ..."`` so that its numbers are never used unknowingly.
    """
    p = PEERS.get(peer)
    if p is None:
        return PeerResult(None, None, f"missing: unknown peer {peer!r}; known: {sorted(PEERS)}")
    res = p.compute(n, d, wavelengths, angles, pol)
    if check and peer != "tmm" and res.status == "ok":
        v = validated(peer)
        if not v.ok:
            return PeerResult(res.R, res.T, v.status)
    return res


ADAPTERS: dict[str, Callable[..., PeerResult]] = {
    name: (lambda n, d, wavelengths, angles, pol, _name=name: compute(_name, n, d, wavelengths, angles, pol)) for name in PEERS
}


def reference(stack: CoherentStack) -> tuple[np.ndarray, np.ndarray]:
    """tmm's R and T for ``stack``, shape (P, A, W). Slow: ~tens of µs per point."""
    b = PEERS["tmm"].build_forward(stack)
    return b.fn()


@dataclass
class Validation:
    peer: str
    version: str | None
    status: str  # "ok (...)" | "missing: ..." | "failed: ..."
    max_abs_dR: float | None = None
    max_abs_dT: float | None = None
    stack: str = ""

    @property
    def ok(self) -> bool:
        return self.status.startswith("ok")


def validate(peer: str, seed: int = 0, tol: float = VALIDATION_TOL, stack: CoherentStack | None = None) -> Validation:
    """Compare ``peer`` with tmm on a random absorbing, dispersive stack (s and p)."""
    p = PEERS[peer]
    stack = stack if stack is not None else random_stack(seed)
    R, T, status = p.compute_stack(stack)
    v = Validation(peer, p.version(), status, stack=f"{stack.name}: {stack.description}, {stack.shape}")
    if R is None:
        return v
    try:
        R0, T0 = reference(stack)
    except Exception as e:  # tmm itself missing
        v.status = f"failed: reference tmm unavailable ({_short_exc(e)})"
        return v
    if R.shape != R0.shape:
        v.status = f"failed: output shape {R.shape} != expected {R0.shape}"
        return v
    v.max_abs_dR = float(np.max(np.abs(R - R0)))
    v.max_abs_dT = float(np.max(np.abs(T - T0)))
    err = max(v.max_abs_dR, v.max_abs_dT)
    if not np.isfinite(err) or err > tol:
        v.status = (
            f"failed: disagrees with tmm on a random absorbing stack "
            f"(max|dR|={v.max_abs_dR:.2e}, max|dT|={v.max_abs_dT:.2e} > tol {tol:g})"
        )
    else:
        v.status = f"ok (max|dR|={v.max_abs_dR:.1e}, max|dT|={v.max_abs_dT:.1e} vs tmm)"
    return v
