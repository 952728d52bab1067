"""Kernels of the optics, on arrays: Fresnel coefficients (fresnel), coherent film packets — the Rouard/Airy
recursion (coherent), its closed-form derivatives (coherent_derivatives) and the cosine and sine it
computes in vectorizable arithmetic (cos_sin) —, thick incoherent layers (incoherent), the adding rule's
hemispherical sums (adding_sums) and the Gauss–Legendre nodes of hemispherical integrals (quadrature).

Imports only layerstack_jax._base.
"""

# attaches the custom JVP rules of coherent._rouard and coherent._packet: every import of a kernel
# runs this package first, so the forward kernels never run without their derivatives
from . import coherent_derivatives as coherent_derivatives
