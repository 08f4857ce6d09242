"""Compile and load generated code so that it can be checked and used.

The C is compiled with the system compiler in strict C99 mode
(``-std=c99 -Wall -Wextra -Werror -pedantic``) into a shared library and
loaded with ctypes; the struct layouts are rebuilt from the model's sizes,
which the header also states, so no header parser is needed.
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


class CompiledFilter:
    """A generated C filter loaded through ctypes.

    Holds its own params, matrices, transition, filter and workspace structs,
    exactly as an embedded caller would.
    """

    def __init__(self, library: Path, model: str, sizes: dict[str, int], parameter_names: list[str], scalar: str = "double"):
        self.model = model
        self.lib = ctypes.CDLL(str(library))
        real = ctypes.c_double if scalar == "double" else ctypes.c_float
        self.dtype = np.float64 if scalar == "double" else np.float32
        n = sizes["n"]
        dims = {k: max(v, 1) for k, v in sizes.items()}
        mat = real * n * n

        class Params(ctypes.Structure):
            _fields_ = [(name, real) for name in parameter_names]

        class Matrices(ctypes.Structure):
            _fields_ = [
                ("F", real * sizes["nnz_f"]),
                ("G", real * dims["nnz_g"]),
                ("q", real * dims["nw"]),
                ("H", real * dims["nnz_h"]),
                ("r", real * dims["nm"]),
            ]

        class Transition(ctypes.Structure):
            _fields_ = [("Phi", mat), ("Qd", mat)]

        class Filter(ctypes.Structure):
            _fields_ = [("x", real * n), ("P", mat)]

        class Workspace(ctypes.Structure):
            _fields_ = [
                ("A", mat),
                ("B", mat),
                ("S", mat),
                ("Gamma", real * dims["nw"] * n),
                ("M", mat),
                ("Pn", mat),
                ("xn", real * n),
                ("HP", real * n * dims["nm"]),
                ("L", real * dims["nm"] * dims["nm"]),
                ("K", real * dims["nm"] * n),
                ("C", real * dims["nm"] * n),
                ("nu", real * dims["nm"]),
            ]

        self.params, self.matrices = Params(), Matrices()
        self.transition, self.filter, self.workspace = Transition(), Filter(), Workspace()
        self.n, self.nm = n, sizes["nm"]
        self.real = real
        getattr(self.lib, f"{model}_default_params")(ctypes.byref(self.params))
        self._discretize = getattr(self.lib, f"{model}_discretize")
        self._discretize.argtypes = [ctypes.c_void_p, real, ctypes.c_void_p, ctypes.c_void_p]
        self._discretize.restype = ctypes.c_int
        self._update = getattr(self.lib, f"{model}_update", None)
        if self._update is not None:
            self._update.restype = ctypes.c_int

    # -- the filter cycle --------------------------------------------------
    def set_parameters(self, values: dict[str, float]) -> None:
        for name, value in values.items():
            setattr(self.params, name, value)
        getattr(self.lib, f"{self.model}_matrices_evaluate")(ctypes.byref(self.params), ctypes.byref(self.matrices))

    def discretize(self, T: float) -> int:
        return self._discretize(
            ctypes.addressof(self.matrices), T, ctypes.addressof(self.transition), ctypes.addressof(self.workspace)
        )

    def predict(self) -> None:
        getattr(self.lib, f"{self.model}_predict")(
            ctypes.byref(self.filter), ctypes.byref(self.transition), ctypes.byref(self.workspace)
        )

    def update(self, z: np.ndarray) -> int:
        if self._update is None:
            raise ModelError(f"model {self.model!r} has no measurements")
        zc = (self.real * max(self.nm, 1))(*[float(v) for v in z])
        return self._update(ctypes.byref(self.filter), zc, ctypes.byref(self.matrices), ctypes.byref(self.workspace))

    # -- views ---------------------------------------------------------------
    def set_state(self, x: np.ndarray, P: np.ndarray) -> None:
        self._view(self.filter.x)[:] = x
        self._view(self.filter.P)[:] = P

    def _view(self, array) -> np.ndarray:
        return np.ctypeslib.as_array(array)

    @property
    def x(self) -> np.ndarray:
        return self._view(self.filter.x).astype(float)

    @property
    def P(self) -> np.ndarray:
        return self._view(self.filter.P).astype(float)

    @property
    def Phi(self) -> np.ndarray:
        return self._view(self.transition.Phi).astype(float)

    @property
    def Qd(self) -> np.ndarray:
        return self._view(self.transition.Qd).astype(float)


def build_c_filter(folder: Path, model: str, sizes: dict[str, int], parameter_names: list[str], build_dir: Path | None = None) -> CompiledFilter:
    """Compile ``folder/<model>.c`` strictly and load it."""
    build_dir = Path(build_dir or tempfile.mkdtemp(prefix="modelgen-build-"))
    library = compile_shared_library([Path(folder) / f"{model}.c"], build_dir / f"lib{model}.so")
    return CompiledFilter(library, model, sizes, parameter_names)
