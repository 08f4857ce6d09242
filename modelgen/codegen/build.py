"""Compile and load generated code so that it can be checked and used.

The C is compiled with the system compiler in strict C99 mode
(``-std=c99 -Wall -Wextra -Werror -pedantic``) into a shared library and
loaded with ctypes; the struct layouts are rebuilt from the model's sizes and
the code-generation options by ``layout.c_layout``, the description the
header itself was rendered from, so no header parser is needed.
"""

from __future__ import annotations

import ctypes
import hashlib
import importlib.util
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path
from types import ModuleType

import numpy as np

from modelgen.codegen.layout import ModelSizes, c_layout
from modelgen.codegen.options import CodegenOptions
from modelgen.errors import ModelError

STRICT_FLAGS = ("-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic")


def compiler() -> str:
    """The C compiler to use: $CC, else cc or gcc on PATH."""
    for name in (os.environ.get("CC"), "cc", "gcc"):
        if name and shutil.which(name):
            return name
    raise ModelError("no C compiler found (set CC or install gcc)")


def compile_shared_library(c_files: list[Path], output: Path, extra_flags: tuple[str, ...] = ("-O2",)) -> Path:
    """Compile ``c_files`` into a shared library; raise with the compiler's output on failure."""
    command = [compiler(), *STRICT_FLAGS, *extra_flags, "-fPIC", "-shared", "-o", str(output), *map(str, c_files), "-lm"]
    result = subprocess.run(command, capture_output=True, text=True)
    if result.returncode != 0:
        raise ModelError(f"compiling {', '.join(map(str, c_files))} failed:\n{result.stderr}")
    return output


def load_python_module(path: Path) -> ModuleType:
    """Import a generated Python module from its file, under a unique name."""
    path = Path(path)
    digest = hashlib.sha1(str(path.resolve()).encode()).hexdigest()[:10]
    name = f"modelgen_generated_{path.stem}_{digest}"
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise ModelError(f"{path}: cannot be imported as a Python module")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
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
    return ModelSizes(**{k: int(sizes[k]) for k in ("n", "nw", "nm", "nnz_f", "nnz_g", "nnz_h")})


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
        return self._view(self.transition.Phi).astype(float)

    @property
    def Qd(self) -> np.ndarray:
        """Q_d as a full matrix, whatever the transition stores."""
        if self.options.ud:
            gamma = self._view(self.transition.Gamma).astype(float)[:, : self.nw]
            return (gamma * self._view(self.transition.qw).astype(float)[: self.nw]) @ gamma.T
        qd = self._view(self.transition.Qd).astype(float)
        if not self.options.packed:
            return qd
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
    left in the system's temporary folder.
    """
    if build_dir is not None:
        library = compile_shared_library([Path(folder) / f"{model}.c"], Path(build_dir) / f"lib{model}.so", extra_flags)
        return CompiledFilter(library, model, sizes, parameter_names, options=options)
    with tempfile.TemporaryDirectory(prefix="modelgen-build-") as temporary:
        library = compile_shared_library([Path(folder) / f"{model}.c"], Path(temporary) / f"lib{model}.so", extra_flags)
        return CompiledFilter(library, model, sizes, parameter_names, options=options)
