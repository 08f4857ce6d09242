"""Compile and load generated code so that it can be checked and used.

The C is compiled with the system compiler in strict C99 mode
(``-std=c99 -Wall -Wextra -Werror -pedantic``) into a shared library and
loaded with ctypes; the struct layouts are rebuilt from the model's sizes and
the code-generation options by ``layout.c_layout``, the description the
header itself was rendered from, so no header parser is needed.

Compiled libraries can be kept in an on-disk cache (``cache=True``): the
paper's model is about 400 kB of C that gcc -O2 needs seconds for, and every
Monte Carlo worker, every ``modelgen simulate`` and every check of unchanged
code would otherwise compile it again.  An entry is keyed by a digest of
everything the compiler reads or is told: the C files and the headers beside
them, the flags, and the compiler's resolved path and ``--version`` text.  It
lives in ``$MODELGEN_CACHE_DIR`` (an absolute path: a relative one is refused),
else ``$XDG_CACHE_HOME/modelgen`` (if absolute, as the XDG rule says), else
``~/.cache/modelgen`` (folder ``libraries``).  An entry is written under a
temporary name and then linked to its final name, which never replaces an
existing file: two builders of the same code both succeed and one entry
stays.  Each entry carries a header with its key and the digest of the
library; a file at an entry's name that does not verify (cut short, corrupt,
not modelgen's) is left alone and the library is compiled again under the
next name.  A hit copies the library to the caller's output path, so what is
loaded is the caller's own file, as without the cache.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import importlib.util
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from modelgen.codegen.kernel_cache import disk_cached_kernel
from modelgen.codegen.layout import ModelSizes, c_layout
from modelgen.codegen.options import CodegenOptions
from modelgen.errors import ModelError
from modelgen.fileio.cache_entry import link_new_entry
from modelgen.fileio.cache_eviction import cap_bytes, keep_within_cap, mark_used
from modelgen.fileio.output import write_bytes_atomically

STRICT_FLAGS = ("-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic")
#: The C++ backend's class and drivers: the same strictness in C++17.
CXX_STRICT_FLAGS = ("-std=c++17", "-Wall", "-Wextra", "-Werror", "-pedantic")


def compiler() -> str:
    """The C compiler to use: $CC, else cc or gcc on PATH."""
    for name in (os.environ.get("CC"), "cc", "gcc"):
        if name and shutil.which(name):
            return name
    raise ModelError("no C compiler found (set CC or install gcc)")


def cxx_compiler() -> str | None:
    """The C++ compiler to use: $CXX, else c++ or g++ on PATH; None when there is none."""
    for name in (os.environ.get("CXX"), "c++", "g++", "clang++"):
        if name and shutil.which(name):
            return name
    return None


def compile_shared_library(c_files: list[Path], output: Path, extra_flags: tuple[str, ...] = ("-O2",),
                           cache: bool = False, language: str = "c") -> Path:
    """Compile ``c_files`` into a shared library at ``output``; raise with the compiler's output on failure.

    ``cache=True`` takes the library from the compile cache (module
    docstring) when the same sources were compiled with the same compiler
    and flags before, and keeps a newly compiled one there.  ``language``
    ``c++``: C++17 sources (the C++ backend) with the C++ compiler, the
    ``.hpp`` headers beside them in the key; its undefined symbols (the C
    filter's) are resolved when it is loaded after the C library.
    """
    if language == "c++":
        cc = cxx_compiler()
        if cc is None:
            raise ModelError("no C++ compiler found (set CXX or install g++)")
        strict = CXX_STRICT_FLAGS
    else:
        cc, strict = compiler(), STRICT_FLAGS
    flags = [*strict, *extra_flags, "-fPIC", "-shared"]
    headers = ("*.h", "*.hpp") if language == "c++" else ("*.h",)
    key = library_key(c_files, [*flags, "-lm"], compiler_identity(cc), headers, build=Path(output).parent) if cache else None
    if key is not None:
        payload = cached_library(library_cache_folder(), key)
        if payload is not None:
            write_bytes_atomically(Path(output), payload, mode=0o755)  # as the compiler's -o would
            return output
    command = [cc, *flags, "-o", str(output), *map(str, c_files), "-lm"]
    result = subprocess.run(command, capture_output=True, text=True)
    if result.returncode != 0:
        raise ModelError(f"compiling {', '.join(map(str, c_files))} failed:\n{result.stderr}")
    if key is not None:
        store_library(library_cache_folder(), key, Path(output).read_bytes())
    return output


# -- the compile cache (module docstring) ----------------------------------------------

#: Environment variable naming the cache folder (tests point it at a temporary folder).
CACHE_ENV = "MODELGEN_CACHE_DIR"
#: First line of every cache entry; a new layout of entries changes the number.
ENTRY_MAGIC = b"modelgen-library-cache 1\n"
#: Names tried for one key: a file at a name that does not verify is left alone and the next is used.
ENTRY_NAMES = 4


def library_cache_folder() -> Path:
    """The folder of cached libraries: $MODELGEN_CACHE_DIR, else $XDG_CACHE_HOME/modelgen, else ~/.cache/modelgen."""
    cap_bytes()  # a bad $MODELGEN_CACHE_MAX_MB is refused here, before any work, not once a library is built
    explicit = os.environ.get(CACHE_ENV)
    if explicit:
        if not os.path.isabs(explicit):  # the cache would follow the working folder (and land in a report's)
            raise ModelError(f"${CACHE_ENV} {explicit!r} is not an absolute path: the compile cache would move with "
                             "the working folder; give an absolute path")
        return Path(explicit) / "libraries"
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg) if xdg and os.path.isabs(xdg) else Path.home() / ".cache"  # the XDG rule: relative is ignored
    return base / "modelgen" / "libraries"


def compiler_identity(name: str) -> str:
    """The compiler's resolved path and ``--version`` text: a compiler upgrade is a different compiler."""
    path = os.path.realpath(shutil.which(name) or name)
    try:
        modified = os.stat(path).st_mtime_ns
    except OSError:
        modified = 0
    return _identity(path, modified)


@functools.lru_cache(maxsize=8)
def _identity(path: str, modified: int) -> str:
    result = subprocess.run([path, "--version"], capture_output=True, text=True)
    return f"{path}\n{result.returncode}\n{result.stdout}"


def library_key(c_files: list[Path], flags: list[str], identity: str, header_patterns: tuple[str, ...] = ("*.h",),
                build: Path | None = None) -> str:
    """Digest of what a compile reads or is told: sources, the headers beside them, flags, compiler.

    ``build`` is the folder the library is built in (a temporary one, as a
    check's): a ``-L`` flag naming it is ``-L<build>`` in the key, so that
    the same compile in another folder is the same entry; each library a
    ``-l:NAME`` flag links from a ``-L`` folder is keyed by its content
    (read here), not by where it lies.
    """
    folders = sorted({Path(f).resolve().parent for f in c_files})
    headers = sorted(h for folder in folders for pattern in header_patterns for h in folder.glob(pattern))
    linked = _linked_libraries(flags)
    if build is not None:
        flags = [_normalized_flag(flag, Path(build)) for flag in flags]
    digest = hashlib.sha256(ENTRY_MAGIC)
    digest.update(json.dumps({"compiler": identity, "flags": flags,
                              "sources": [Path(f).name for f in c_files]}).encode("utf-8"))
    for path in [*map(Path, c_files), *headers, *linked]:
        content = path.read_bytes()
        digest.update(f"\n{path.name} {len(content)}\n".encode("utf-8"))
        digest.update(content)
    return digest.hexdigest()


def _normalized_flag(flag: str, build: Path) -> str:
    """``-L<build>`` for a ``-L`` flag naming the build folder, else ``flag`` as it is.

    Only a search folder of the linker is normalized: it is not written into
    the library (an ``-rpath`` or ``-I`` folder may be, and stays in the key).
    """
    if flag.startswith("-L") and len(flag) > 2 and os.path.realpath(flag[2:]) == os.path.realpath(build):
        return "-L<build>"
    return flag


def _linked_libraries(flags: list[str]) -> list[Path]:
    """The files of the ``-l:NAME`` flags, found in the ``-L`` folders (in order, as the linker searches them)."""
    folders = [Path(flag[2:]) for flag in flags if flag.startswith("-L") and len(flag) > 2]
    found = []
    for flag in flags:
        if flag.startswith("-l:"):
            found += [folder / flag[3:] for folder in folders if (folder / flag[3:]).is_file()][:1]
    return found


def _entry_paths(folder: Path, key: str) -> list[Path]:
    return [folder / (f"{key}.lib" if k == 0 else f"{key}.{k}.lib") for k in range(ENTRY_NAMES)]


def _entry(key: str, payload: bytes) -> bytes:
    """An entry: magic, key, the library's digest and length, then the library."""
    return ENTRY_MAGIC + f"{key}\n{hashlib.sha256(payload).hexdigest()}\n{len(payload)}\n".encode("ascii") + payload


def _verified_payload(path: Path, key: str) -> bytes | None:
    """The library in the entry at ``path`` if it is a whole entry of ``key``, else None (not trusted)."""
    try:
        data = path.read_bytes()
    except OSError:
        return None
    if not data.startswith(ENTRY_MAGIC):
        return None
    fields = data[len(ENTRY_MAGIC):].split(b"\n", 3)
    if len(fields) != 4 or fields[0] != key.encode("ascii"):
        return None
    payload = fields[3]
    if fields[2] != str(len(payload)).encode("ascii") or fields[1] != hashlib.sha256(payload).hexdigest().encode("ascii"):
        return None
    return payload


def cached_library(folder: Path, key: str) -> bytes | None:
    """The cached library of ``key`` (the first entry that verifies, marked used for the size cap), or None."""
    for path in _entry_paths(folder, key):
        if path.exists():
            payload = _verified_payload(path, key)
            if payload is not None:
                mark_used(path)
                return payload
    return None


def store_library(folder: Path, key: str, payload: bytes) -> Path | None:
    """Keep ``payload`` as the entry of ``key``; its path, or None if it could not be kept.

    The entry is written to a temporary file and hard-linked to the first
    free name, which fails rather than replace a file: an entry of the same
    key another builder linked first is kept (and used), a file that does not
    verify is left alone and the next name tried.  Only the temporary file,
    ours, is removed.  A cache that cannot be written (read-only, no room, no
    hard links) just stays without the entry: the caller has its library.
    The cache is then kept within its size cap, least recently used entries
    first (:func:`modelgen.fileio.cache_eviction.keep_within_cap`).
    """
    kept = link_new_entry(folder, key, lambda handle: handle.write(_entry(key, payload)), _entry_paths(folder, key),
                          lambda path: path if _verified_payload(path, key) is not None else None)
    if kept is not None:
        keep_within_cap(folder.parent, stored=kept)
    return kept


#: The numba-compiled predict kernel (``_compiled_predict``) of each generated module text this process has loaded,
#: by the SHA-256 of the text: numba compiles on the first call (about 2 s) and keeps nothing on disk for a
#: module loaded from a file, so a module loaded again from the same text (another folder, another test,
#: another check) takes the kernel compiled for the first.  Numba freezes the module's globals (N_STATES, the
#: _KERNEL_* arrays) into the kernel as constants: they are part of the text, so the same text means the same
#: kernel.  Nothing is written beside the module; with $MODELGEN_KERNEL_CACHE_DIR set, the kernel is also kept
#: on disk there for other processes (:mod:`modelgen.codegen.kernel_cache`).
_COMPILED_PREDICT_BY_TEXT: dict[str, Any] = {}


def load_python_module(path: Path) -> ModuleType:
    """Import a generated Python module from its file, under a unique name.

    Its numba predict kernel is the one already compiled in this process for the same module text, if any
    (:data:`_COMPILED_PREDICT_BY_TEXT`), else the module's own, cached on disk when $MODELGEN_KERNEL_CACHE_DIR is
    set (:func:`modelgen.codegen.kernel_cache.disk_cached_kernel`).
    """
    path = Path(path)
    digest = hashlib.sha1(str(path.resolve()).encode()).hexdigest()[:10]
    name = f"modelgen_generated_{path.stem}_{digest}"
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise ModelError(f"{path}: cannot be imported as a Python module")
    try:
        text = path.read_bytes()
    except OSError as exc:
        raise ModelError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    kernel = getattr(module, "_compiled_predict", None)
    if getattr(module, "COMPILED", False) and hasattr(kernel, "py_func"):  # a numba dispatcher
        text_digest = hashlib.sha256(text).hexdigest()
        if text_digest not in _COMPILED_PREDICT_BY_TEXT:
            _COMPILED_PREDICT_BY_TEXT[text_digest] = disk_cached_kernel(kernel, text)
        module._compiled_predict = _COMPILED_PREDICT_BY_TEXT[text_digest]
    return module


def _ctypes_struct(name: str, fields, real) -> type:
    """A ctypes Structure with the members of a layout field list."""

    def array(dims):
        t = real
        for d in reversed(dims):
            t = t * d.value
        return t

    return type(name, (ctypes.Structure,), {"_fields_": [(f.name, array(f.dims)) for f in fields]})


def _model_sizes(sizes: dict[str, int] | ModelSizes) -> ModelSizes:
    if isinstance(sizes, ModelSizes):
        return sizes
    return ModelSizes(**{k: int(sizes[k]) for k in ("n", "nw", "nm", "nnz_f", "nnz_g", "nnz_h", "nnz_phi")})


class CompiledFilter:
    """A generated C filter loaded through ctypes.

    Holds its own params, matrices, transition, filter and workspace structs,
    exactly as an embedded caller would.  Their members come from
    ``layout.c_layout`` -- the same description the header was rendered from
    -- so every option combination loads the same way; the covariance is set
    and read through the generated set_covariance/get_covariance, whatever
    its storage (full, packed or U D U^T).
    """

    def __init__(
        self,
        library: Path,
        model: str,
        sizes: dict[str, int] | ModelSizes,
        parameter_names: list[str],
        scalar: str = "double",
        options: CodegenOptions | None = None,
    ):
        options = options or CodegenOptions(scalar=scalar)
        self.options = options
        self.model = model
        self.lib = ctypes.CDLL(str(library))
        real = ctypes.c_double if options.scalar == "double" else ctypes.c_float
        self.dtype = np.float64 if options.scalar == "double" else np.float32
        sizes = _model_sizes(sizes)
        layout = c_layout(sizes, options, model.upper())
        fields = [(name, real) for name in parameter_names] or [("unused_", real)]  # C has no empty structs
        Params = type("Params", (ctypes.Structure,), {"_fields_": fields})
        self.params = Params()
        self.matrices = _ctypes_struct("Matrices", layout.matrices, real)()
        self.transition = _ctypes_struct("Transition", layout.transition, real)()
        self.filter = _ctypes_struct("Filter", layout.filter, real)()
        self.workspace = type("Workspace", (ctypes.Union,), {"_fields_": [
            ("discretize", _ctypes_struct("DiscretizeScratch", layout.discretize_scratch, real)),
            ("filter", _ctypes_struct("FilterScratch", layout.filter_scratch, real)),
        ]})()
        self.n, self.nm, self.nw = sizes.n, sizes.nm, sizes.nw
        self.real = real
        self._square = real * sizes.n * sizes.n
        getattr(self.lib, f"{model}_default_params")(ctypes.byref(self.params))
        self._discretize = self._function("discretize", [ctypes.c_void_p, real, ctypes.c_void_p, ctypes.c_void_p])
        self._predict = self._function("predict", [ctypes.c_void_p] * 3)
        self._set_covariance = self._function("set_covariance", [ctypes.c_void_p] * 3)
        self._get_covariance = getattr(self.lib, f"{model}_get_covariance")
        self._get_covariance.argtypes = [ctypes.c_void_p, ctypes.c_void_p]
        self._get_covariance.restype = None
        self._get_transition_matrix = getattr(self.lib, f"{model}_get_transition_matrix")
        self._get_transition_matrix.argtypes = [ctypes.c_void_p, ctypes.c_void_p]
        self._get_transition_matrix.restype = None
        self._set_transition_matrix = self._function("set_transition_matrix", [ctypes.c_void_p] * 2)
        self._update = getattr(self.lib, f"{model}_update", None)
        if self._update is not None:
            self._update.argtypes = [ctypes.c_void_p] * 4
            self._update.restype = ctypes.c_int
            self._update_masked = self._function("update_masked", [ctypes.c_void_p] * 7)
        self._reset = getattr(self.lib, f"{model}_reset_error_state")
        self._reset.argtypes = [ctypes.c_void_p]
        self._reset.restype = None

    def _function(self, name: str, argtypes: list) -> ctypes._CFuncPtr:
        fn = getattr(self.lib, f"{self.model}_{name}")
        fn.argtypes = argtypes
        fn.restype = ctypes.c_int
        return fn

    # -- the filter cycle --------------------------------------------------
    def set_parameters(self, values: dict[str, float]) -> int:
        """Set parameters and evaluate the matrices; returns matrices_evaluate's status."""
        for name, value in values.items():
            setattr(self.params, name, value)
        evaluate = getattr(self.lib, f"{self.model}_matrices_evaluate")
        evaluate.restype = ctypes.c_int
        return int(evaluate(ctypes.byref(self.params), ctypes.byref(self.matrices)))

    def discretize(self, T: float) -> int:
        return self._discretize(
            ctypes.addressof(self.matrices), T, ctypes.addressof(self.transition), ctypes.addressof(self.workspace)
        )

    def predict(self) -> int:
        return self._predict(ctypes.byref(self.filter), ctypes.byref(self.transition), ctypes.byref(self.workspace))

    def update(self, z: np.ndarray) -> int:
        if self._update is None:
            raise ModelError(f"model {self.model!r} has no measurements")
        zc = (self.real * max(self.nm, 1))(*[float(v) for v in z])
        return self._update(ctypes.byref(self.filter), zc, ctypes.byref(self.matrices), ctypes.byref(self.workspace))

    def update_masked(self, z: np.ndarray, mask: np.ndarray | None) -> tuple[int, np.ndarray, float]:
        """The generated update_masked: (status, innovation before the update, NIS); mask None uses all."""
        if self._update is None:
            raise ModelError(f"model {self.model!r} has no measurements")
        dim = max(self.nm, 1)
        zc = (self.real * dim)(*[float(v) for v in z])
        maskc = None if mask is None else (ctypes.c_ubyte * dim)(*[1 if v else 0 for v in mask])
        innovation, nis = (self.real * dim)(), self.real(np.nan)
        status = self._update_masked(
            ctypes.byref(self.filter), zc, maskc, ctypes.byref(self.matrices), innovation, ctypes.byref(nis),
            ctypes.byref(self.workspace),
        )
        return int(status), np.array(innovation[: self.nm], dtype=float), float(nis.value)

    def reset_error_state(self) -> None:
        """The generated reset_error_state: x := 0 after feedback, P unchanged."""
        self._reset(ctypes.byref(self.filter))

    # -- views ---------------------------------------------------------------
    def set_state(self, x: np.ndarray, P: np.ndarray) -> int:
        """Set x and P (through the generated set_covariance); returns its status."""
        self._view(self.filter.x)[:] = x
        buffer = self._square()
        np.ctypeslib.as_array(buffer)[:] = np.asarray(P, dtype=float)
        return self._set_covariance(ctypes.byref(self.filter), buffer, ctypes.byref(self.workspace))

    def set_estimate(self, x: np.ndarray) -> None:
        """Overwrite x alone, as a C caller does through the filter struct (e.g. after feedback)."""
        self._view(self.filter.x)[:] = x

    def _view(self, array) -> np.ndarray:
        return np.ctypeslib.as_array(array)

    @property
    def x(self) -> np.ndarray:
        return self._view(self.filter.x).astype(float)

    @property
    def P(self) -> np.ndarray:
        buffer = self._square()
        self._get_covariance(ctypes.byref(self.filter), buffer)
        return np.ctypeslib.as_array(buffer).astype(float)

    @property
    def Phi(self) -> np.ndarray:
        """Phi as a full matrix (the generated get_transition_matrix expands the compressed transition)."""
        buffer = self._square()
        self._get_transition_matrix(ctypes.byref(self.transition), buffer)
        return np.ctypeslib.as_array(buffer).astype(float)

    @functools.cached_property
    def phi_entries(self) -> tuple[np.ndarray, np.ndarray]:
        """(rows, columns) of the transition's stored Phi entries, read from the C itself.

        A scratch transition holding 1, 2, ... in its stored entries is
        expanded by the generated get_transition_matrix: entry k lands at its
        (row, column), so no index table or index type is assumed here.
        """
        scratch = type(self.transition)()
        stored = self._view(scratch.Phi)
        stored[:] = np.arange(1, stored.size + 1)
        buffer = self._square()
        self._get_transition_matrix(ctypes.byref(scratch), buffer)
        dense = np.ctypeslib.as_array(buffer).astype(float)
        rows, cols = np.nonzero(dense)
        order = np.argsort(dense[rows, cols])
        return rows[order].astype(np.int64), cols[order].astype(np.int64)

    def set_transition_matrix(self, Phi: np.ndarray) -> int:
        """The generated set_transition_matrix from a full Phi; returns its status (ERR_STRUCTURE off the pattern).

        A float build receives Phi rounded to float, as its C caller would pass it.
        """
        Phi = np.asarray(Phi, dtype=float)
        buffer = self._square()
        target = np.ctypeslib.as_array(buffer)
        if Phi.shape != target.shape:
            raise ValueError(f"set_transition_matrix: Phi has shape {Phi.shape}, expected {target.shape}")
        target[:] = Phi
        return self._set_transition_matrix(ctypes.byref(self.transition), buffer)

    @property
    def Qd(self) -> np.ndarray:
        """Q_d as a full matrix, whatever the transition stores."""
        if self.options.ud:
            gamma = self._view(self.transition.Gamma).astype(float)[:, : self.nw]
            return (gamma * self._view(self.transition.qw).astype(float)[: self.nw]) @ gamma.T
        qd = self._view(self.transition.Qd).astype(float)  # the packed upper triangle (codegen.layout)
        full = np.zeros((self.n, self.n))
        full[np.triu_indices(self.n)] = qd
        return full + np.triu(full, 1).T


def build_c_filter(
    folder: Path,
    model: str,
    sizes: dict[str, int] | ModelSizes,
    parameter_names: list[str],
    build_dir: Path | None = None,
    options: CodegenOptions | None = None,
    extra_flags: tuple[str, ...] = ("-O2",),
) -> CompiledFilter:
    """Compile ``folder/<model>.c`` strictly and load it (``options``: those it was generated with).

    Without ``build_dir`` the library is built in a temporary folder that is
    removed once it is loaded (a loaded library stays mapped), so nothing is
    left in the system's temporary folder.  The compile cache is used: the
    same code, compiler and flags compiled cleanly before compile cleanly now.
    """
    if build_dir is not None:
        library = compile_c_library(folder, model, Path(build_dir), extra_flags)
        return CompiledFilter(library, model, sizes, parameter_names, options=options)
    with tempfile.TemporaryDirectory(prefix="modelgen-build-") as temporary:
        library = compile_c_library(folder, model, Path(temporary), extra_flags)
        return CompiledFilter(library, model, sizes, parameter_names, options=options)


def compile_c_library(folder: Path, model: str, build_dir: Path, extra_flags: tuple[str, ...] = ("-O2",)) -> Path:
    """``folder/<model>.c`` compiled strictly into ``build_dir/lib<model>.so``, through the compile cache."""
    return compile_shared_library([Path(folder) / f"{model}.c"], Path(build_dir) / f"lib{model}.so", extra_flags, cache=True)
