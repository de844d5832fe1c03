"""Numerical kernels compiled with numba: loops over samples or grid cells that array operations would run as many
passes with temporaries."""

from __future__ import annotations

import functools

#: Every kernel of the modules imported so far (:func:`load_kernels`).
_KERNELS: list[Kernel] = []


class Kernel:
    """A function compiled by numba in nopython mode for one signature, on its first call or :meth:`load`, its
    machine code cached on disk.

    Loading (numba's import and its first kernel's type registries, ~0.5 s) waits for a kernel's first use, so a
    command that needs none (``fcso --help``, the paper's measure) does not pay it. The cache lives next to the
    function's module or in ``NUMBA_CACHE_DIR``: compiling the design's kernels takes 2-3 s, loading them ~0.3 s.
    Where no folder is writable (a read-only install without a writable home) each process compiles its kernels
    instead. Other argument types still compile on first use.
    """

    def __init__(self, function, signature: str):
        functools.update_wrapper(self, function)
        self.function, self.signature, self._compiled = function, signature, None

    def load(self):
        """The compiled kernel (numba's dispatcher), compiled or loaded from the cache once."""
        if self._compiled is None:
            import numba

            try:
                kernel = numba.njit(cache=True, nogil=True)(self.function)
            except RuntimeError:
                kernel = numba.njit(nogil=True)(self.function)
            kernel.compile(self.signature)
            self._compiled = kernel
        return self._compiled

    def __call__(self, *args):
        return (self.load() if self._compiled is None else self._compiled)(*args)


def compiled(signature: str):
    """Decorator: the function as a :class:`Kernel` compiled for ``signature``.

    Parameters
    ----------
    signature : str
        The argument types, numba's notation, e.g. ``"(float32[:, ::1], int64)"``.
    """

    def kernel(function) -> Kernel:
        made = Kernel(function, signature)
        _KERNELS.append(made)
        return made

    return kernel


def load_kernels() -> None:
    """Load every kernel of the modules imported so far, before workers fork: each forked worker then has them
    (loaded on first use in each worker instead, the 12-part job loaded them 67 times, ~0.07 s each)."""
    for kernel in _KERNELS:
        kernel.load()
