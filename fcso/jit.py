"""Numerical kernels compiled with numba: loops over samples or grid cells that array operations would run as many
passes with temporaries."""

from __future__ import annotations

import numba


def compiled(signature: str):
    """Decorator: the function compiled by numba in nopython mode for ``signature`` when its module is imported, its
    machine code cached on disk.

    Compiled at import, the kernels are in every worker forked after it: compiled on first use, each forked worker
    loaded them again from the cache (the 12-part job: 67 loads, ~0.07 s each). Other argument types still compile
    on first use. The cache lives next to the function's module or in ``NUMBA_CACHE_DIR``: compiling the design's
    four kernels takes 2-3 s, loading them ~0.3 s. Where no folder is writable (a read-only install without a
    writable home) each process compiles its kernels instead.

    Parameters
    ----------
    signature : str
        The argument types, numba's notation, e.g. ``"(float32[:, ::1], int64)"``.
    """

    def compile_(function):
        try:
            kernel = numba.njit(cache=True, nogil=True)(function)
        except RuntimeError:
            kernel = numba.njit(nogil=True)(function)
        kernel.compile(signature)
        return kernel

    return compile_
