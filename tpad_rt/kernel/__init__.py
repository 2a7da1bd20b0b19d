"""numba kernels: texture evaluation, the render block, the simulated plate.

Every function here is ``@numba.njit(cache=True, nogil=True)``, allocates nothing
per call and touches no Python object (docs/kernel.md). Public wrappers that
validate and allocate live outside this package (``tpad_rt.pipeline``,
``tpad_rt.texture``).
"""
