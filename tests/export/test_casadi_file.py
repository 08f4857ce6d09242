"""modelgen.export.casadi_file: the serialized CasADi Function loads back and evaluates to the sympy matrices."""

from __future__ import annotations

import casadi as ca
import numpy as np
from click.testing import CliRunner

from modelgen.cli import main
from modelgen.derivation.symbolic import parameter_vector
from modelgen.export.casadi_file import casadi_function, to_casadi
from modelgen.export.readable import MATRIX_NAMES, nonzero_entries
from modelgen.model.loading import load_model


def test_the_function_file_loads_with_casadi_and_agrees_with_sympy(enu_derived, enu_values, tmp_path):
    path = tmp_path / "enu.casadi"
    path.write_text(to_casadi(enu_derived), encoding="ascii")
    loaded = ca.Function.load(str(path))
    assert loaded.name() == "enu_doppler18_matrices"
    assert [loaded.name_out(k) for k in range(loaded.n_out())] == list(MATRIX_NAMES)
    outputs = loaded(*parameter_vector(enu_derived.model, enu_values))
    reference = enu_derived.numeric(enu_values)
    for name, value in zip(MATRIX_NAMES, outputs):
        np.testing.assert_allclose(value.full(), reference[name], rtol=1e-14, atol=0, err_msg=name)


def test_zero_entries_stay_structural_zeros(enu_derived):
    function = casadi_function(enu_derived)
    for k, name in enumerate(MATRIX_NAMES):
        assert function.sparsity_out(k).nnz() == len(nonzero_entries(getattr(enu_derived, name))), name


def test_cli_derive_format_casadi_writes_a_loadable_file(tmp_path):
    out = tmp_path / "ned.casadi"
    run = CliRunner().invoke(main, ["derive", "ned_doppler18", "--format", "casadi", "--out", str(out)])
    assert run.exit_code == 0, run.output
    loaded = ca.Function.load(str(out))
    assert loaded.name_in() == load_model("ned_doppler18").parameter_names
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ned.casadi"]


def test_inputs_are_named_as_the_parameters_and_carry_their_defaults(enu_derived, enu_values, tmp_path):
    """Called by name, the loaded function fills the other inputs from the model's defaults (NaN where it has none)."""
    path = tmp_path / "enu.casadi"
    path.write_text(to_casadi(enu_derived), encoding="ascii")
    loaded = ca.Function.load(str(path))
    parameters = enu_derived.model.parameters
    assert loaded.name_in() == [q.name for q in parameters]
    for k, q in enumerate(parameters):
        default = float(loaded.default_in(k))
        assert (np.isnan(default) and q.value is None) or default == q.value, q.name
    given = {q.name: enu_values[q.name] for q in parameters if q.name in enu_values and q.value is None}
    result = loaded(**given)
    reference = enu_derived.numeric({**{q.name: q.value for q in parameters if q.value is not None}, **given})
    for name in MATRIX_NAMES:
        np.testing.assert_allclose(result[name].full(), reference[name], rtol=1e-14, atol=0, err_msg=name)
    missing = next(q.name for q in parameters if q.value is None and q.name in given)
    assert np.isnan(loaded(**{k: v for k, v in given.items() if k != missing})["F"].full()).any()
