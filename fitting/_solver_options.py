"""What a fit is asked to do: the solver methods (:data:`METHODS`, :data:`HOST_METHODS`), the
solver choice and stopping rules (:class:`SolverOptions`), the solver coordinates of a start
(:func:`starting_point`), the refusal of a host method where a compiled one is needed
(:func:`require_compiled_method`) and the multi-start give-up rule that never fires
(:data:`NEVER`, a plain fit's)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from layerstack_jax import LayerstackError

from ._objective import Objective
from ._structured import STRUCTURE_MODES

__all__ = ["METHODS", "HOST_METHODS", "SolverOptions", "starting_point", "require_compiled_method", "NEVER"]

METHODS = ("lm", "gauss-newton", "dogleg", "bfgs", "lbfgsb", "trf")
#: Methods run on the host (scipy), one fit at a time.
HOST_METHODS = ("trf",)


@dataclasses.dataclass(frozen=True)
class SolverOptions:
    """Solver choice and stopping rules.

    ``rtol``/``atol``: optimistix step and cost tolerances on the unconstrained coordinates;
    ``gtol``: L-BFGS-B tolerance on the projected gradient of :math:`\\tfrac12\\|r\\|^2` (in z);
    ``max_steps``: iteration limit; ``sigma_tol``: the least-squares methods (``lm``,
    ``gauss-newton``, ``dogleg``) also stop as soon as the Gauss–Newton step still to go is
    shorter than ``sigma_tol`` standard errors (:func:`fitting._least_squares.gauss_newton_distance`; 0 turns that
    rule off, leaving optimistix's step and cost test alone); ``structure``: the Jacobian's
    form (:data:`fitting._structured.STRUCTURE_MODES`) — ``"auto"`` uses the compressed,
    block-structured Jacobian of spectral parameters free per wavelength where it pays
    (:func:`fitting._fit_functions.structure_for`), ``"dense"`` never, ``"structured"`` always
    (an error where the fit has no such structure).
    """

    method: str = "lm"
    rtol: float = 1e-10
    atol: float = 1e-12
    gtol: float = 1e-9
    max_steps: int = 256
    sigma_tol: float = 1e-3
    structure: str = "auto"

    def __post_init__(self):
        if self.method not in METHODS:
            raise LayerstackError(f"method must be one of {METHODS}, got {self.method!r}")
        if self.structure not in STRUCTURE_MODES:
            raise LayerstackError(f"structure must be one of {STRUCTURE_MODES}, got {self.structure!r}")
        if not (isinstance(self.max_steps, (int, np.integer)) and self.max_steps >= 1):
            raise LayerstackError(f"max_steps must be an integer >= 1, got {self.max_steps!r}")
        for name in ("rtol", "atol", "gtol"):
            if not getattr(self, name) > 0:
                raise LayerstackError(f"{name} must be > 0, got {getattr(self, name)}")
        if not (isinstance(self.sigma_tol, (int, float, np.floating)) and 0 <= self.sigma_tol < 1):
            raise LayerstackError(f"sigma_tol must be in [0, 1) standard errors, got {self.sigma_tol!r}")


def starting_point(objective: Objective, o: SolverOptions, x0) -> np.ndarray:
    """Solver coordinates of physical ``x0`` (``(..., P)``)."""
    layout = objective.layout
    if o.method in ("lbfgsb", "trf"):
        return np.asarray(x0, float) / layout.scale
    return layout.to_unconstrained(x0)


def require_compiled_method(caller: str, method: str) -> None:
    """Refuse a host method (:data:`HOST_METHODS`: one fit at a time on the host) where
    ``caller`` needs a compiled, batched solver; the message names the methods that are."""
    if method in HOST_METHODS:
        compiled = ", ".join(repr(m) for m in METHODS if m not in HOST_METHODS)
        raise LayerstackError(f"{caller}: method {method!r} runs on the host one fit at a time; batched fits need a "
                              f"compiled solver: {compiled}")


#: The give-up rule ``(steps, cost)`` that never fires: a plain fit's (Python scalars: one
#: compiled program serves every rule).
NEVER = (2 ** 31 - 1, math.inf)
