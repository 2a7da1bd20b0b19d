"""Ahead-of-time kernels: the audio callbacks as a shared library that needs only libc.

:mod:`tpad_rt.aot.build` compiles them with numba and links them with the system C
compiler; :mod:`tpad_rt.aot.library` finds and loads that library with ctypes, without
importing numba. docs/kernel.md "Ahead-of-time kernels" is the design.
"""
