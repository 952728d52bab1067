"""The columns ``layerstack predict`` writes for a geometry: the command line's own vocabulary,
kept here rather than on the physics' ``Geometry`` interface.

* :func:`prediction_columns` — ``[(column name, geometry)]`` for one ``-g`` spelling
  (``specular:θ`` gives ``R_θ``, ``T_θ``, ``A_θ``; every other geometry one column);
* :func:`polarized_columns` — the polarization-resolved columns of ``--polarization``
  (``brdf:I:V`` geometries only: ``f_AB`` or the 16 Mueller elements, Ellis 1996);
* :func:`supports_polarization` — whether a geometry has such columns.

Each is a :func:`functools.singledispatch` function registered on the public geometry classes:
a geometry the command line has nothing special for falls back to the default.
"""

from __future__ import annotations

from functools import singledispatch

import numpy as np

import layerstack_jax as ls


@singledispatch
def prediction_columns(geometry, text: str) -> list:
    """``[(column name, geometry)]`` that ``layerstack predict -g text`` writes: one column."""
    return [(text, geometry)]


@prediction_columns.register(ls.Specular)
def _specular_columns(geometry, text: str) -> list:
    """``specular:θ`` gives three columns ``R_θ, T_θ, A_θ``; ``specular:θ:Q`` gives ``Q_θ``."""
    parts = text.split(":")
    angle = parts[1].strip()
    quantities = ("R", "T", "A") if len(parts) == 2 else (geometry.quantity,)
    return [(f"{q}_{angle}", ls.Specular(geometry.angle_deg, q)) for q in quantities]


@singledispatch
def polarized_columns(geometry, stack, wavelength_nm, name: str, polarization: str, nodes: int) -> dict:
    """Polarization-resolved columns for ``layerstack predict --polarization``: none here."""
    raise ls.LayerstackError(f"geometry {name!r}: --polarization applies to brdf:I:V geometries only")


@polarized_columns.register(ls.BRDF)
def _brdf_polarized_columns(geometry, stack, wavelength_nm, name, polarization, nodes) -> dict:
    """Diffuse part, 1/sr: ``f_AB`` (A illumination, B analyser, s or p) or the 16 Mueller
    elements ``GEOM_mIJ`` (Ellis 1996), of the ideal instrument."""
    if not geometry.ideal:
        raise ls.LayerstackError(f"geometry {name!r}: --polarization models the ideal instrument only "
                                 "(no apertures, no cover glass)")
    i, v = geometry.incidence_deg, geometry.viewing_deg
    if polarization == "mueller":
        M = np.asarray(ls.diffuse_mueller(stack, wavelength_nm, i, v, nodes=nodes), dtype=float)
        return {f"{name}_m{a}{b}": M[a, b] for a in range(4) for b in range(4)}
    f = np.asarray(ls.polarized_brdf(stack, wavelength_nm, i, v, nodes=nodes), dtype=float)
    a, b = ("sp".index(c) for c in polarization)
    return {f"{name}_{polarization}": f[a, b]}


def supports_polarization(geometry) -> bool:
    """True when :func:`polarized_columns` has columns for ``geometry``'s class."""
    return polarized_columns.dispatch(type(geometry)) is not polarized_columns.dispatch(object)
