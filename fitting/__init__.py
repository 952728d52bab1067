"""Inverse problems and coating design on top of :mod:`layerstack_jax`.

Not implemented yet: parameter objects, objectives, optimistix/jaxopt solvers, joint and
batched fits and design are the subject of the fitting and design issues. Importing this
package gives nothing but this notice, on purpose.
"""

__all__: list[str] = []
