r"""The leaves of a stack and their roles, declared where each field is defined.

Every number of a :class:`~layerstack_jax.Stack` is a pytree leaf: a thickness, α(λ), ρg(λ), an
index n or k, a dispersion coefficient, a Kubelka–Munk K(λ). Three clients need to know more
about a leaf than its value, and they learn it from the field that holds it — declared with
:func:`leaf` (equinox field metadata) in the module that defines the field, never from a table
kept elsewhere:

* **axes** (batched prediction, :func:`~layerstack_jax.predict`): a ``"spectral"`` leaf is a
  scalar, ``(1,)`` or ``(wl,)`` for one stack (it broadcasts against ``(*batch, wl)``); a
  ``"vector"`` leaf (the default: tabulated values, Sellmeier terms) is ``(m,)`` for one stack.
* **optics** (the fixed Fresnel algebra, :func:`~layerstack_jax.fixed_optics`): ``fixed`` if
  changing the leaf leaves the :class:`~layerstack_jax.Optics` unchanged (a thick layer's α, a
  background's ρg, every number of a scattering body under the binder); a callable of the field's
  owner when it depends on a static flag (a layer's thickness: fixed when the layer is
  incoherent). A declaration covers everything below the field (a ρg given as a table is fixed
  optics in all its leaves). Default: not fixed — the safe side (the algebra is recomputed).
* **fit** (the fitting layer): ``per_wavelength`` fields holding a spectrum are freed one value
  per wavelength by default; ``file_key`` is the field's key in a stack file (``thickness_nm``,
  ``rho_g``), the name ``layerstack predict --vary LAYER.KEY`` sets.

:func:`stack_leaves` walks a stack and returns, for each leaf in ``jax.tree_util`` order, its
path, a readable name, the field that holds it and that field's role. :func:`leaf_role_at` answers
for a path (the fitting layer's parameter paths).
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any, Callable, NamedTuple, Optional, Union

import equinox as eqx
import jax

__all__ = ["LeafRole", "Leaf", "leaf", "role_of", "stack_leaves", "leaf_role_at", "optics_fixed_at", "file_fields",
           "replace_at"]

_KEY = "layerstack_leaf"


class LeafRole(NamedTuple):
    """The declared role of a field (module docstring).

    ``axes``: ``"spectral"`` or ``"vector"``; ``optics``: True, False, or ``owner -> bool``;
    ``per_wavelength``: a fit frees a spectrum held here per wavelength; ``file_key``: the
    stack-file key, or None when the field is not a number of the file."""

    axes: str = "vector"
    optics: Union[bool, Callable[[Any], bool]] = False
    per_wavelength: bool = False
    file_key: Optional[str] = None

    def fixed_optics(self, owner) -> bool:
        """True if changing this field of ``owner`` leaves the fixed optics unchanged."""
        return bool(self.optics(owner)) if callable(self.optics) else bool(self.optics)


_UNDECLARED = LeafRole()


def leaf(*, spectral: bool = False, fixed_optics: Union[bool, Callable[[Any], bool]] = False,
         per_wavelength: bool = False, file_key: Optional[str] = None, **kwargs):
    """An ``equinox.field`` declaring the role of the leaves it holds (module docstring);
    other keyword arguments (``converter``, ``default`` …) go to ``equinox.field``."""
    if "static" in kwargs:
        raise TypeError("leaf(): a static field holds no leaves; use equinox.field(static=True)")
    role = LeafRole("spectral" if spectral else "vector", fixed_optics, per_wavelength, file_key)
    return eqx.field(metadata={_KEY: role}, **kwargs)


@functools.lru_cache(maxsize=None)
def _roles(cls) -> dict:
    return {f.name: f.metadata.get(_KEY, _UNDECLARED) for f in dataclasses.fields(cls)} \
        if dataclasses.is_dataclass(cls) else {}


def role_of(owner, field: str) -> LeafRole:
    """The declared role of ``field`` of the module ``owner`` (the default role if undeclared)."""
    return _roles(type(owner)).get(field, _UNDECLARED)


def file_fields(owner) -> dict:
    """``{file key: field name}`` of the fields of ``owner`` declared with a ``file_key``."""
    return {r.file_key: name for name, r in _roles(type(owner)).items() if r.file_key is not None}


class Leaf(NamedTuple):
    """One leaf of a stack: ``path`` (field names and sequence positions from the stack:
    ``("layers", 0, "thickness")``), ``name`` (for messages: ``layers[0] ('varnish').thickness``),
    ``role`` (of the field holding it) and ``fixed_optics`` (some field on its path declares that
    changing it leaves the optics unchanged)."""

    path: tuple
    name: str
    role: LeafRole
    fixed_optics: bool


def _key(k):
    if isinstance(k, jax.tree_util.GetAttrKey):
        return k.name
    if isinstance(k, jax.tree_util.SequenceKey):
        return k.idx
    return getattr(k, "key", k)  # pragma: no cover - dict keys do not occur in a stack


def _walk(tree, path: tuple):
    """``(role, fixed optics, readable name)`` of the leaf at ``path`` of ``tree`` (canonical keys);
    a path may end inside an array leaf (an element index), which keeps its field's role."""
    obj, parts, role, fixed = tree, [], _UNDECLARED, False
    for i, key in enumerate(path):
        if isinstance(key, str):
            role = role_of(obj, key)
            fixed = fixed or role.fixed_optics(obj)
            obj = getattr(obj, key)
            parts.append(f".{key}")
        elif isinstance(obj, (tuple, list)):
            obj = obj[key]
            label = getattr(obj, "name", "") if path[:i] == ("layers",) else ""  # a layer: its name too
            parts.append(f"[{key}]" + (f" ({label!r})" if label else ""))
        else:  # an element of an array leaf
            parts.append(f"[{key}]")
    return role, fixed, "".join(parts).lstrip(".")


def stack_leaves(stack) -> list[Leaf]:
    """Per leaf of ``jax.tree_util.tree_flatten(stack)``, in that order: its :class:`Leaf`."""
    out = []
    for kp, _ in jax.tree_util.tree_flatten_with_path(stack)[0]:
        path = tuple(_key(k) for k in kp)
        role, fixed, name = _walk(stack, path)
        out.append(Leaf(path, name, role, fixed))
    return out


def leaf_role_at(tree, path: tuple) -> LeafRole:
    """The role of the field holding the leaf at ``path`` (canonical: names and positions)."""
    return _walk(tree, path)[0]


def optics_fixed_at(tree, path: tuple) -> bool:
    """True if changing the value at ``path`` leaves the fixed optics unchanged (module docstring)."""
    return _walk(tree, path)[1]


def replace_at(tree, path: tuple, value):
    """``tree`` with the value at ``path`` replaced, every module on the way rebuilt through its
    constructor (``dataclasses.replace``: converters and ``__check_init__`` run, so the new
    value is checked as if it had been given at construction)."""
    if not path:
        return value
    head, rest = path[0], path[1:]
    if isinstance(head, str):
        return dataclasses.replace(tree, **{head: replace_at(getattr(tree, head), rest, value)})
    items = list(tree)
    items[head] = replace_at(items[head], rest, value)
    return type(tree)(items)
