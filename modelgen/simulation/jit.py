"""Compiling the simulation's inner loops with numba, when it is installed.

A 4-hour flight mechanized at 300 Hz is 4.3 million strapdown steps; a Python
loop needs minutes for that, a compiled loop well under a second per million
steps.  The hot loops (trajectory generation, mechanization) are written as
plain Python over numpy arrays and decorated with :func:`compiled`.  With numba
present they are compiled (and cached on disk next to the source); without it
they run unchanged as Python, slowly but with identical results, so numba is a
speed dependency, never a correctness one.
"""

from __future__ import annotations

from typing import Callable, TypeVar

F = TypeVar("F", bound=Callable)

try:  # pragma: no cover - which branch runs depends on the environment
    import numba as _numba

    HAVE_NUMBA = True
except ImportError:  # pragma: no cover
    _numba = None
    HAVE_NUMBA = False


def compiled(function: F) -> F:
    """``numba.njit(cache=True)`` if numba is installed, else the function itself."""
    if _numba is None:
        return function
    return _numba.njit(cache=True, fastmath=False, nogil=True)(function)  # type: ignore[return-value]


def compiled_in_memory(function: F) -> F:
    """``numba.njit`` without the disk cache if numba is installed, else the function itself.

    For a loop that takes a function compiled at run time as an argument (the
    navigator's ``mechanize`` and a model's generated ``navigation_rates``):
    each specialization names that function's type, which no later process
    has, so a disk entry could never be reused, and numba's cache index, which
    pickles every specialization's type, fails once an earlier model's
    function has been freed ("underlying object has vanished").
    """
    if _numba is None:
        return function
    return _numba.njit(fastmath=False, nogil=True)(function)  # type: ignore[return-value]


def inlined(function: F) -> F:
    """:func:`compiled`, and inlined by numba into its compiled callers (no call: arguments and tuples stay in registers).

    For small helpers of a hot loop.  Only for helpers whose callers are in the
    same file: numba's on-disk cache of a caller notices changes to its own
    file, not to another's.
    """
    if _numba is None:
        return function
    return _numba.njit(cache=True, fastmath=False, nogil=True, inline="always")(function)  # type: ignore[return-value]


@compiled
def _first_call(x):
    """The smallest compiled function: calling it loads what any first compiled call loads."""
    return x + 1.0


def load_compiled_machinery() -> None:
    """Load numba's typing and target registries now (about 0.2 s, else paid by a process's first compiled call).

    A Monte Carlo worker does this in its import thread, while the caller
    still makes the study's set-up (:func:`modelgen.simulation.montecarlo.warm_worker`).
    """
    _first_call(1.0)
