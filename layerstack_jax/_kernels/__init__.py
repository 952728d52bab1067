"""Kernels of the optics, on arrays: Fresnel coefficients (fresnel), coherent film packets — the Rouard/Airy
recursion (coherent), thick incoherent layers (incoherent), the adding rule's hemispherical sums
(adding_sums) and the Gauss–Legendre nodes of hemispherical integrals (quadrature).

Imports only layerstack_jax._base.
"""
