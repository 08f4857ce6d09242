"""A disk cache of the generated Python modules' compiled predict kernels, on request ($MODELGEN_KERNEL_CACHE_DIR).

numba compiles a generated module's ``_compiled_predict`` on its first call
(about 2 s of CPU for the paper's model) and, for a module loaded from a
file of its own, keeps nothing on disk: every process that loads the module
compiles it again.  With ``$MODELGEN_KERNEL_CACHE_DIR`` naming a folder (an
absolute path), :func:`disk_cached_kernel` gives the kernel numba's own disk
cache (``cache=True``) there instead, so that a later process (another
check, another xdist worker of the test suite) loads the compiled kernel
(about 0.2 s) instead of compiling it.

The cache can never serve a stale kernel: the kernel is compiled as if from
``kernel_<sha256>.py``, a copy of the module's exact text named by the
SHA-256 of that text, in the folder; numba keys its cached code by that
file's own content hash, the function's line, the numba and Python versions
and the CPU, and the module's globals the kernel freezes in (its sizes and
sparsity pattern) are part of the text.  The same text is the same kernel;
any other text is another file.

Off unless asked for, because nothing would bound it: numba's files
(about 350 kB a model) are not entries modelgen writes and can verify, so
the capped cache of compiled libraries (:mod:`modelgen.fileio.cache_eviction`)
neither counts nor removes them.  The test suite turns it on for a folder of
its run (tests/conftest.py), where its xdist workers share the kernels.  A
folder that cannot be written just leaves the kernel compiled in memory.
"""

from __future__ import annotations

import hashlib
import os
import sys
import types
from pathlib import Path
from typing import Any

from modelgen.errors import ModelError
from modelgen.fileio.output import write_bytes_atomically

#: Environment variable naming the kernel cache's folder; unset or empty: no disk cache.
KERNEL_CACHE_ENV = "MODELGEN_KERNEL_CACHE_DIR"


def kernel_cache_folder() -> Path | None:
    """The folder of ``$MODELGEN_KERNEL_CACHE_DIR``, or None when it is unset; a relative path is refused."""
    value = os.environ.get(KERNEL_CACHE_ENV)
    if not value:
        return None
    if not os.path.isabs(value):  # the cache would follow the working folder
        raise ModelError(f"${KERNEL_CACHE_ENV} {value!r} is not an absolute path: the kernel cache would move with "
                         "the working folder; give an absolute path")
    return Path(value)


def kernel_source(folder: Path, text: bytes) -> Path:
    """The copy of a module's ``text`` in ``folder``, named by its SHA-256 (written whole if missing or different)."""
    path = folder / f"kernel_{hashlib.sha256(text).hexdigest()}.py"
    try:
        same = path.read_bytes() == text
    except OSError:
        same = False
    if not same:
        write_bytes_atomically(path, text)
    return path


def as_if_from(function: types.FunctionType, source: Path, globals_: dict) -> types.FunctionType:
    """``function`` with its code marked as coming from ``source`` and ``globals_`` as its globals (same code,
    defaults and closure)."""
    code = function.__code__.replace(co_filename=str(source))
    moved = types.FunctionType(code, globals_, function.__name__, function.__defaults__, function.__closure__)
    moved.__qualname__, moved.__module__, moved.__doc__ = function.__qualname__, globals_["__name__"], function.__doc__
    return moved


def text_module(function: types.FunctionType, text: bytes) -> types.ModuleType:
    """A module of the same globals as ``function``'s, named ``modelgen_kernel_<sha256 of text>`` in every process.

    numba's cached code names its function's module (its globals'
    ``__name__``) and imports it by that name when it loads the code; a
    generated module's own name depends on its path
    (modelgen.codegen.build.load_python_module), which another process does
    not share.  The copy of the globals is registered under the text's name
    (the first module of that text in this process); the kernel reads its
    globals only when numba compiles it, which freezes them.
    """
    name = f"modelgen_kernel_{hashlib.sha256(text).hexdigest()}"
    if name not in sys.modules:
        module = types.ModuleType(name)
        module.__dict__.update({k: v for k, v in function.__globals__.items() if k != "__name__"})
        sys.modules[name] = module
    return sys.modules[name]


def disk_cached_kernel(kernel: Any, text: bytes) -> Any:
    """The numba dispatcher ``kernel`` of a module of ``text``, cached on disk when the folder is set, else ``kernel``.

    The new dispatcher has ``kernel``'s options (``nogil``) and numba's
    ``cache=True``; if the copy cannot be written (no room, no permission,
    something not a regular file at its name) or numba finds no writable
    cache folder, ``kernel`` itself is returned (compiled in memory).
    """
    folder = kernel_cache_folder()
    if folder is None:
        return kernel
    import numba  # installed: kernel is one of its dispatchers

    try:
        source = kernel_source(folder, text)
        function = as_if_from(kernel.py_func, source, text_module(kernel.py_func, text).__dict__)
        return numba.jit(cache=True, **kernel.targetoptions)(function)
    except (OSError, ModelError, RuntimeError):  # ModelError: not a regular file; RuntimeError: numba found no folder
        return kernel
