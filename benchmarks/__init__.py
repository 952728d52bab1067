"""Benchmarks for layerstack_jax and peer thin-film solvers: ``python -m benchmarks --help``.

Importing this package imports numpy only; peers and frameworks are imported inside the
benchmark worker processes.
"""
