"""The C backend's run: a scenario flown through the compiled C, loaded with ctypes (codegen/build.py)."""

from __future__ import annotations

from pathlib import Path

from modelgen.codegen.backends.base import Scenario, Trajectory, named_parameters
from modelgen.codegen.build import build_c_filter, compile_c_library
from modelgen.codegen.layout import ModelSizes
from modelgen.codegen.options import CodegenOptions
from modelgen.derivation.symbolic import DerivedModel
from modelgen.errors import ModelError


def c_run(folder: Path, derived: DerivedModel, scenario: Scenario, options: CodegenOptions,
          build_dir: Path | None = None) -> Trajectory:
    """x and P after every step, by ``folder/<model>.c`` compiled strictly (through the compile cache)."""
    model = derived.model
    filt = build_c_filter(Path(folder), model.name, ModelSizes.of(derived), model.parameter_names, build_dir, options=options)
    filt.set_parameters(named_parameters(derived, scenario))
    if filt.discretize(scenario.step) != 0:
        raise ModelError(f"generated C for {model.name!r} refused the step T = {scenario.step}")
    filt.set_state(scenario.x0(), scenario.initial_covariance)
    out = []
    for z in scenario.measurements(derived):
        filt.predict()
        if derived.n_measurements:
            status = filt.update(z)
            if status != 0:
                raise ModelError(f"generated C update returned status {status}")
        out.append((filt.x, filt.P))
    return out


def c_prepare(folder: Path, derived: DerivedModel, options: CodegenOptions, build_dir: Path) -> None:
    """The library :func:`c_run` in ``build_dir`` loads, compiled ahead into the compile cache (Backend.prepare)."""
    compile_c_library(folder, derived.model.name, build_dir)
