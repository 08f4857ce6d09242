"""The C++ backend's run: a scenario flown through modelgen::<model>::Filter, compiled strictly as C++17.

The driver (``harness/cpp_run_driver.cpp.j2``) is a shared library of one
``extern "C"`` function that sets the parameters, discretizes, sets x and P
and runs predict and update over the scenario's measurements, returning x
and P after every step.  It is linked against the C library of the same
folder (compiled through the compile cache, as the C backend's run builds
it) under a name carrying the library's digest, found beside it at load
time ($ORIGIN): the class's arithmetic is that library's.  The driver is
compiled through the compile cache too (keyed on its source and headers,
the flags with the build folder normalized and the C library's content).  With Eigen
installed the driver reads x and P through the class's Eigen views.
"""

from __future__ import annotations

import ctypes
import hashlib
import shutil
import tempfile
from pathlib import Path

import numpy as np

from modelgen.codegen.backends.base import BackendUnavailable, Scenario, Trajectory, environment, named_parameters
from modelgen.codegen.backends.cpp.context import cpp_context
from modelgen.codegen.build import compile_shared_library, cxx_compiler
from modelgen.codegen.description import describe_filter
from modelgen.codegen.options import CodegenOptions
from modelgen.derivation.symbolic import DerivedModel
from modelgen.errors import ModelError

HERE = Path(__file__).resolve().parent

#: Where Debian's libeigen3-dev puts Eigen (.ci/run installs it); without it the class has plain arrays only.
EIGEN_INCLUDE = Path("/usr/include/eigen3")

#: The failing call of the driver's status (its status // 100).
CALLS = {1: "evaluate", 2: "discretize", 3: "set_state", 4: "set_covariance", 5: "predict", 6: "update"}


def eigen_flags() -> tuple[str, ...]:
    """``-isystem`` of Eigen where it is installed (a system header: its own warnings are not the class's)."""
    return (f"-isystem{EIGEN_INCLUDE}",) if (EIGEN_INCLUDE / "Eigen" / "Core").is_file() else ()


def build_driver(folder: Path, derived: DerivedModel, options: CodegenOptions, build: Path) -> Path:
    """The C library of ``folder`` and the C++ driver linked against it, in ``build``; the driver's path."""
    name = derived.model.name
    c_library = compile_shared_library([folder / f"{name}.c"], build / f"lib{name}.so", ("-O2",), cache=True)
    digest = hashlib.sha256(c_library.read_bytes()).hexdigest()[:16]
    linked = build / f"lib{name}_c_{digest}.so"  # the name the driver records: this library and no other
    shutil.copyfile(c_library, linked)
    sources = build / "cpp"
    sources.mkdir(exist_ok=True)
    for header in (f"{name}.h", f"{name}.hpp"):
        shutil.copyfile(folder / header, sources / header)
    driver = sources / f"{name}_run.cpp"
    template = environment(HERE / "templates", HERE / "harness").get_template("cpp_run_driver.cpp.j2")
    driver.write_text(template.render(cpp_context(describe_filter(derived, options))), encoding="utf-8")
    flags = ("-O1", *eigen_flags(), f"-L{build}", "-Wl,--no-as-needed", f"-l:{linked.name}", "-Wl,-rpath,$ORIGIN")
    # the compile cache keys the driver on its source, the headers beside it, the flags with ``build`` as <build>
    # and the content of the C library it links: a driver built in another (temporary) folder is a hit
    return compile_shared_library([driver], build / f"lib{name}_cpp_{digest}.so", flags, cache=True, language="c++")


def cpp_run(folder: Path, derived: DerivedModel, scenario: Scenario, options: CodegenOptions,
            build_dir: Path | None = None) -> Trajectory:
    """x and P after every step, by the C++ class (the driver built in ``build_dir``, else a temporary folder)."""
    if cxx_compiler() is None:
        raise BackendUnavailable("no C++ compiler found (set CXX or install g++): the C++ class is not checked")
    if build_dir is not None:
        return _fly(build_driver(Path(folder), derived, options, Path(build_dir)), derived, scenario)
    with tempfile.TemporaryDirectory(prefix="modelgen-cpp-") as temporary:
        return _fly(build_driver(Path(folder), derived, options, Path(temporary)), derived, scenario)


def _fly(driver: Path, derived: DerivedModel, scenario: Scenario) -> Trajectory:
    n = derived.n_states
    measurements = np.asarray(scenario.measurements(derived), dtype=float)
    steps = len(measurements)
    parameters = list(named_parameters(derived, scenario).values())
    inputs = np.concatenate([parameters, [scenario.step], scenario.x0(), np.asarray(scenario.initial_covariance, float).ravel(),
                             measurements.ravel()]).astype(np.float64)
    outputs = np.zeros(steps * (n + n * n))
    library = ctypes.CDLL(str(driver))  # loads the C library it names, beside it
    run = library.modelgen_cpp_run
    run.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_void_p]
    run.restype = ctypes.c_int
    status = run(inputs.ctypes.data, steps, outputs.ctypes.data)
    if status:
        raise ModelError(f"the generated C++ for {derived.model.name!r}: {CALLS.get(status // 100, '?')} returned status {status % 100}")
    out = outputs.reshape(steps, n + n * n)
    return [(row[:n].copy(), row[n:].reshape(n, n).copy()) for row in out]
