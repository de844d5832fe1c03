"""Numerical kernels compiled with numba: loops over samples or grid cells that array operations would run as many
passes with temporaries."""

from __future__ import annotations

import numba


def compiled(function):
    """``function`` compiled by numba in nopython mode, its machine code cached on disk.

    The cache lives next to the function's module or in ``NUMBA_CACHE_DIR``:
    compiling the design's four kernels takes 2-3 s, loading them from the
    cache ~0.4 s, in every process. Where no folder is writable (a read-only install without a
    writable home) each process compiles its kernels instead.
    """
    try:
        return numba.njit(cache=True, nogil=True)(function)
    except RuntimeError:
        return numba.njit(nogil=True)(function)
