"""Rendering coated objects with Mitsuba 3 (optional extra: ``pip install 'layerstack-jax[render]'``).

Hirayama et al. §5: reflectance tables of the coating, pre-computed over angle and wavelength,
are interpolated by a ray tracer. :func:`coated_bsdf` turns a ``CoatingTables`` into a Mitsuba
BSDF (spectral variants: vectorized ``llvm_ad_spectral``/``cuda_ad_spectral``, or scalar);
:func:`best_variant` names the fastest variant usable here; :func:`render_vjp` carries the
gradient of a rendered image back to the coating's parameters (tables from
:func:`coating_table_values`);
:mod:`layerstack_jax.render._scenes` builds the scenes of the paper's Figs. 8–9. Mitsuba is
imported only when one of these functions is called, never by ``import layerstack_jax``.

Importing this subpackage points Dr.Jit at an LLVM ≥ 17 when ``DRJIT_LIBLLVM_PATH`` is unset
and one is installed (:mod:`layerstack_jax.render._llvm`): with older ones its LLVM backend
aborts.
"""

from ._differentiable import coating_table_values as coating_table_values
from ._differentiable import render_vjp as render_vjp
from ._llvm import best_variant as best_variant
from ._llvm import configure as _configure_llvm
from ._lookup import DEFENSIVE as DEFENSIVE
from ._lookup import CoatingTables as CoatingTables
from ._lookup import TableSurface as TableSurface
from ._mitsuba import PLUGIN_NAME as PLUGIN_NAME
from ._mitsuba import coated_bsdf as coated_bsdf
from ._mitsuba import import_mitsuba as import_mitsuba
from ._mitsuba import register as register

_configure_llvm()

__all__ = [
    "best_variant",
    "coated_bsdf",
    "coating_table_values",
    "CoatingTables",
    "DEFENSIVE",
    "import_mitsuba",
    "PLUGIN_NAME",
    "register",
    "render_vjp",
    "TableSurface",
]
