"""Stacks and their exits: the Stack pytree and its exit media (stack), Kubelka–Munk scattering bodies
(kubelka_munk), the mixed coherent/incoherent recursion at a Snell invariant (recursion) and a stack under
collimated and diffuse light (illumination).

Imports layerstack_jax._base, ._kernels and ._media.
"""
