"""The Python backend's run: a scenario flown through the generated module, as a user imports it."""

from __future__ import annotations

from pathlib import Path

from modelgen.codegen.backends.base import Scenario, Trajectory, named_parameters
from modelgen.codegen.build import load_python_module
from modelgen.codegen.options import CodegenOptions
from modelgen.derivation.symbolic import DerivedModel


def python_run(folder: Path, derived: DerivedModel, scenario: Scenario, options: CodegenOptions,
               build_dir: Path | None = None) -> Trajectory:
    """x and P after every step, by ``folder/<model>.py`` (the module does not depend on the options; nothing is built)."""
    gen = load_python_module(Path(folder) / f"{derived.model.name}.py")
    p = gen.parameter_vector(named_parameters(derived, scenario))
    F, G, H = gen.system_matrix(p), gen.noise_input_matrix(p), gen.measurement_matrix(p)
    q, r = gen.noise_psd(p), gen.measurement_variance(p)
    phi, qd = gen.discretize(F, G, q, scenario.step)
    x = scenario.x0()
    P = scenario.initial_covariance.copy()
    out = []
    for z in scenario.measurements(derived):
        x, P = gen.predict(x, P, phi, qd)
        if derived.n_measurements:
            x, P = gen.update(x, P, z, H, r)
        out.append((x, P))
    return out
