"""Materials: dispersion models (materials), oscillator models under ellipsometry software's names
(oscillators), effective media (effective_medium) and the refractiveindex.info database (database).

Imports only layerstack_jax._base.
"""
