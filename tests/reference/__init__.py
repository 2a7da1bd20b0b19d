"""Slow pure-NumPy references for the numba kernels, written from docs/formats.md and the paper.

Each reference works from the validated file models (never from compiled kernel
arrays), vectorised over arrays of inputs; the tests compare every kernel with it.
"""
