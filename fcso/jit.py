"""Numerical kernels compiled with numba: loops over samples or grid cells that array operations would run as many
passes with temporaries."""

from __future__ import annotations

import functools

import numba

#: The kernels of the modules imported so far that load on first use (:func:`compiled_on_use`, :func:`load_kernels`).
_ON_USE: list[Kernel] = []


def _compile(function, signature: str):
    """``function`` compiled by numba for ``signature``, its machine code cached on disk where a folder is writable."""
    try:
        kernel = numba.njit(cache=True, nogil=True)(function)
    except RuntimeError:
        kernel = numba.njit(nogil=True)(function)
    kernel.compile(signature)
    return kernel


def compiled(signature: str):
    """Decorator: the function compiled by numba in nopython mode for ``signature`` when its module is imported, its
    machine code cached on disk.

    For the kernels every design runs (the screening's). Compiled at import, the kernels are in every worker forked
    after it: compiled on first use, each forked worker loaded them again from the cache (the 12-part job: 67 loads,
    ~0.07 s each). Other argument types still compile on first use. The cache lives next to the function's module or
    in ``NUMBA_CACHE_DIR``: compiling the design's kernels takes 2-3 s, loading them ~0.3 s. Where no folder is
    writable (a read-only install without a writable home) each process compiles its kernels instead.

    Parameters
    ----------
    signature : str
        The argument types, numba's notation, e.g. ``"(float32[:, ::1], int64)"``.
    """

    def compile_(function):
        return _compile(function, signature)

    return compile_


class Kernel:
    """A function compiled as :func:`compiled` does, on its first call or at :func:`load_kernels`."""

    def __init__(self, function, signature: str):
        functools.update_wrapper(self, function)
        self.function, self.signature, self.dispatcher = function, signature, None

    def load(self):
        """The compiled kernel (numba's dispatcher), compiled or loaded from the cache once."""
        if self.dispatcher is None:
            self.dispatcher = _compile(self.function, self.signature)
        return self.dispatcher

    def __call__(self, *args):
        return (self.dispatcher or self.load())(*args)


def compiled_on_use(signature: str):
    """Decorator: the function as a :class:`Kernel` for ``signature``, for kernels only some designs run (the capture
    measure's).

    Loading a kernel costs ~0.01 s once numba's first kernel is loaded; a design that never runs it (the paper's
    measure) does not pay it. A design that runs them calls :func:`load_kernels` before its workers fork, so they
    inherit them as they do :func:`compiled`'s. A kernel that another calls in numba code stays :func:`compiled`:
    numba code calls a dispatcher, not a :class:`Kernel` (the capture measure's row kinds).
    """

    def kernel(function) -> Kernel:
        made = Kernel(function, signature)
        _ON_USE.append(made)
        return made

    return kernel


def load_kernels() -> None:
    """Load every :func:`compiled_on_use` kernel of the modules imported so far (in this process, before workers
    fork)."""
    for kernel in _ON_USE:
        kernel.load()
