"""Foundations every floor uses: array aliases (custom_types), NaN-safe elementary operations (numerics),
validation that names the field (validate), one compiled program per public call (programs), progress
reporting (progress), the declared roles of a stack's leaves (leaves) and the memory that "auto" sizes
may fill (memory).

Imports nothing else from layerstack_jax.
"""
