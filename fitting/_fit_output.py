"""The record a compiled fit returns (:class:`FitOutput`): solution, steps, status and the
statistics' ingredients at the solution."""

from __future__ import annotations

from typing import NamedTuple

from jaxtyping import Array, Float, Int

from ._structured import CompressedJacobian

__all__ = ["FitOutput"]


class FitOutput(NamedTuple):
    """What the compiled fit returns (leading axes: one per fit in batched calls).

    ``x``: physical solution ``(P,)``; ``num_steps``; ``status`` (:data:`fitting._status.STATUS`); ``model``:
    model values per dataset ``(samples, wl)``; ``residuals``: weighted data residuals per
    dataset; ``penalty``: penalty residuals; ``jacobian``: ``(M, P)`` of the full residual vector
    w.r.t. ``x / scale`` (a :class:`~fitting._structured.CompressedJacobian` standing for it
    when the fit uses the block structure of spectral parameters free per wavelength)."""

    x: Float[Array, "*fit P"]
    num_steps: Int[Array, "*fit"]
    status: Int[Array, "*fit"]
    model: tuple[Float[Array, "..."], ...]
    residuals: tuple[Float[Array, "..."], ...]
    penalty: Float[Array, "*fit K"]
    jacobian: Float[Array, "*fit M P"] | CompressedJacobian
