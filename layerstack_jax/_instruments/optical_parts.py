r"""The parts the spectrophotometers (:mod:`.sphere`, :mod:`.directional`, :mod:`.specular`) share:
the optics of a collimated beam at an angle and of the back hemisphere, the cone of directions of
a finite aperture and its mean, the light of the back side that leaves through a specular port,
the cover glass, and the spelling of an instrument's options (``:key=value``).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .._base.validate import (
    LayerstackError,
    check_nonnegative,
    check_positive,
    is_concrete,
)
from .._kernels.fresnel import exit_medium_ratio
from .._kernels.quadrature import DEFAULT_NODES
from .._stacks.illumination import (
    Diffuse,
    _snell,
    diffuse_joined,
    hemisphere,
)
from .._stacks.recursion import natural, stack_intensities, stack_interfaces
from .._stacks.stack import ResolvedStack
from .instrument import cap_measure, check_cone, cone_rule, covered
from .optics import Optics, coherent_films


def _scalar_text(x) -> str:
    return f"{float(x):g}" if is_concrete(x) and jnp.ndim(x) == 0 else "array"


def _incidence(rs: ResolvedStack, angle_deg):
    return stack_interfaces(rs, _snell(rs, angle_deg), both_sides=False)


def _back_hemisphere(rs: ResolvedStack, nodes: int):
    s, weights, reach = hemisphere(rs, "back", nodes)
    return stack_interfaces(rs, s, both_sides=True), weights, reach


def _optics(geometry, rs, incidence, viewing=None, diffuse=None, weights=None, reach=None, nodes=DEFAULT_NODES):
    return Optics(geometry, incidence, viewing, diffuse, weights, tuple(rs.n), coherent_films(rs), nodes, reach)


def _diffuse_back(rs: ResolvedStack, o: Optics) -> Diffuse:
    return diffuse_joined(rs, "back", o.diffuse, o.weights, o.reach)


def _substrate_has_no_diffuse_light() -> LayerstackError:
    return LayerstackError(
        "a specular substrate has no diffuse reflectance factor: measure it with a specular geometry "
        "(Specular(angle), CLI 'specular:ANGLE') or put the stack over a LambertianBackground"
    )


def _split(text: str, kind: str, n_min: int, n_max: int) -> list[str]:
    parts = text.split(":")
    if not n_min <= len(parts) <= n_max:
        raise ValueError(kind)
    return parts


# ----------------------------------------------------------------- non-ideal instruments (issue 15)
# The cover-glass fields are shared by Sphere, Directional and BRDF; they are declared in each
# class after its own fields (not in a base class, whose fields would come first and change the
# positional construction Sphere(8.0, "excluded"), Directional(45.0, 0.0)).


def _is_zero(x) -> bool:
    """True when ``x`` is None or concretely 0 everywhere: that non-ideality is left out and the
    reading is computed exactly as by the ideal instrument (bit for bit)."""
    return x is None or (is_concrete(x) and not np.any(np.asarray(x)))


def _check_cover(name: str, g) -> None:
    """Eager checks of the cover-glass fields of geometry ``g`` (class name ``name``)."""
    if g.cover_index is None:
        return
    if not callable(g.cover_index):
        check_positive(f"{name}.cover_index", g.cover_index)
    check_nonnegative(f"{name}.cover_thickness_nm (nm)", g.cover_thickness_nm)
    check_nonnegative(f"{name}.cover_alpha_per_nm (1/nm)", g.cover_alpha_per_nm)


def _covered(g, rs: ResolvedStack) -> ResolvedStack:
    if g.cover_index is None:
        return rs
    return covered(rs, g.cover_index, g.cover_thickness_nm, g.cover_alpha_per_nm, g.cover_contact)


def _cone_invariants(rs: ResolvedStack, axis_deg, half_angle_deg, nodes: int):
    """Snell invariants :math:`n_0\\sin\\theta_k` ``(*angle, K, 1 | wl)`` of the directions of
    :func:`~layerstack_jax._instruments.instrument.cone_rule` (from their sines: a finite derivative in β
    also where a direction meets the normal)."""
    _, sin_t, _ = cone_rule(axis_deg, half_angle_deg, nodes)
    return jnp.real(jnp.asarray(rs.n[0])) * sin_t[..., None]


def _cone_interfaces(rs: ResolvedStack, axis_deg, half_angle_deg, nodes: int):
    return stack_interfaces(rs, _cone_invariants(rs, axis_deg, half_angle_deg, nodes), both_sides=False)


def _cone_T(rs: ResolvedStack, axis_deg, half_angle_deg, nodes: int):
    """Natural-light collimated transmittance at the cone's directions, ``(*angle, K, 1 | wl)``."""
    s = _cone_invariants(rs, axis_deg, half_angle_deg, nodes)
    return natural(stack_intensities(rs, s, both_sides=False).T_front)


def _cone_mean(T_k, axis_deg, half_angle_deg, nodes: int):
    r"""Projected-solid-angle mean over the cone, :math:`\int T\cos\theta\,d\Omega /
    \int\cos\theta\,d\Omega`, of ``T_k`` ``(*angle, K, wl)`` at the :func:`cone_rule` directions:
    ``(*angle, wl)``. The factor :math:`1-\cos\beta` cancels (finite at β = 0)."""
    cos_t, _, w = cone_rule(axis_deg, half_angle_deg, nodes)
    c = w * cos_t
    c = c / jnp.sum(c, axis=-1, keepdims=True)
    return jnp.sum(c[..., None] * T_k, axis=-2)


def _stale_optics(what: str) -> LayerstackError:
    return LayerstackError(f"optics were made for {what}: rebuild them with fixed_optics() for this geometry")


def _aperture_mean(T, axis_deg, half_angle_deg, nodes: int):
    """``T`` from :class:`Optics` at a point (``half_angle_deg`` None: returned as is) or at the
    :func:`cone_rule` directions (averaged by :func:`_cone_mean`), after checking that the
    optics were made that way: a cone adds an axis of K = 2 nodes² directions before the
    wavelengths (leading batch axes of the stack's leaves may come in front of either)."""
    K = 2 * nodes * nodes
    has_cone_axis = T.ndim >= np.ndim(axis_deg) + 2 and T.shape[-2] == K
    if half_angle_deg is None:
        if has_cone_axis:
            raise _stale_optics("an aperture (a cone of directions), this geometry reads a point")
        return T
    if not has_cone_axis:
        raise _stale_optics("a point or another number of cone_nodes, this geometry reads an aperture")
    return _cone_mean(T, axis_deg, half_angle_deg, nodes)


def _port_escape(rs: ResolvedStack, T_k, axis_deg, half_angle_deg, nodes: int):
    r"""The part of the back-side diffuse transmittance :math:`t_b` that leaves into the specular
    port's cone (half-angle β about the specular direction θ_0), ``(*angle, wl)``:
    :math:`\frac{(n_0/n_g)^2}{\pi}\int_\text{cone} T(\theta)\cos\theta\,d\Omega` — the
    radiance leaving the stack towards θ is :math:`(n_0/n_g)^2 T(\theta)` times that of the
    diffuse flux under it (Simonot eq. 77, reciprocity), and over the whole hemisphere this
    integral is :math:`t_b` itself (eq. 49 with the same reciprocity)."""
    cos_t, _, w = cone_rule(axis_deg, half_angle_deg, nodes)
    ratio = exit_medium_ratio(rs.n[0], rs.n[-1])
    solid = cap_measure(half_angle_deg)[..., None]
    return ratio * solid / jnp.pi * jnp.sum((w * cos_t)[..., None] * T_k, axis=-2)


def _options(text: str, keys: dict, flags: dict) -> dict:
    """``key=value`` and flag options after a geometry's base spelling, as constructor keywords."""
    out = {}
    for part in text:
        if not part:
            continue
        if "=" in part:
            k, v = part.split("=", 1)
            if k not in keys:
                raise LayerstackError(f"unknown option {k!r} (known: {', '.join([*keys, *flags])})")
            out[keys[k]] = float(v)
        elif part in flags:
            out[flags[part]] = True
        else:
            raise LayerstackError(f"unknown option {part!r} (known: {', '.join([*keys, *flags])})")
    return out


def _option_text(g, keys: dict, flags: dict, defaults: dict) -> str:
    """The ``:key=value`` options of ``g`` whose value differs from the class default."""
    out = []
    for k, field in keys.items():
        v = getattr(g, field)
        if v is None or (is_concrete(v) and np.ndim(v) == 0 and float(v) == defaults.get(field)):
            continue
        out.append(f":{k}={_scalar_text(v) if not callable(v) else 'function'}")
    out += [f":{k}" for k, field in flags.items() if getattr(g, field)]
    return "".join(out)


_COVER_OPTIONS = {"cover": "cover_index", "cover_d": "cover_thickness_nm", "cover_alpha": "cover_alpha_per_nm"}
_COVER_FLAGS = {"contact": "cover_contact"}
_COVER_DEFAULTS = {"cover_thickness_nm": 1.0e6, "cover_alpha_per_nm": 0.0}


_APERTURES = (("incidence_deg", "illumination_half_angle_deg"), ("viewing_deg", "viewing_half_angle_deg"))


def _check_apertures(name: str, g) -> None:
    """Each non-zero aperture of ``g`` (Directional, BRDF) a cone above the horizon (eager and under jit)."""
    for axis, half in _APERTURES:
        if not _is_zero(getattr(g, half)):
            check_cone(f"{name}.{half} (degrees)", getattr(g, axis), getattr(g, half))


