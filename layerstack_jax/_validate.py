"""Input validation that names the offending field. Checks run on concrete values only;
traced values (inside jit / grad) are checked with ``equinox.error_if`` where it matters."""

from __future__ import annotations

import jax
import numpy as np

__all__ = ["is_concrete", "check_nonnegative", "check_finite", "check_unit_interval", "LayerstackError"]


class LayerstackError(ValueError):
    """Raised for invalid physical input (the message names the field)."""


def is_concrete(x) -> bool:
    leaves = jax.tree_util.tree_leaves(x)
    return not any(isinstance(leaf, jax.core.Tracer) for leaf in leaves)


def _as_numpy(x):
    return np.asarray(x)


def check_finite(name: str, x) -> None:
    if x is None or not is_concrete(x):
        return
    a = _as_numpy(x)
    if not np.all(np.isfinite(a)):
        raise LayerstackError(f"{name} contains NaN or infinite values")


def check_nonnegative(name: str, x, what: str = "must be >= 0") -> None:
    if x is None or not is_concrete(x):
        return
    check_finite(name, x)
    a = _as_numpy(x)
    if np.any(a < 0):
        raise LayerstackError(f"{name} {what}, got min {a.min()!r}")


def check_unit_interval(name: str, x) -> None:
    if x is None or not is_concrete(x):
        return
    check_finite(name, x)
    a = _as_numpy(x)
    if np.any(a < 0) or np.any(a > 1):
        raise LayerstackError(f"{name} must lie in [0, 1], got range [{a.min()!r}, {a.max()!r}]")
