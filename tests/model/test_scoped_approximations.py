"""Approximations scoped to some rows: ``{name: constant_radii, in: [velocity, attitude]}`` (issue 27).

The textbook 21-state model of ``test_ins_gnss21_nav`` (Shin 2005 ch. 4, Groves 2013 ch. 14)
neglects the variation of the radii of curvature everywhere; a model that keeps
dR/dL in its position rows but not in its velocity and attitude rows (the set of
simplifications the issue's published package uses) is written by scoping
``constant_radii``.  Its rows must then equal, exactly, the textbook's where the
approximation applies and the model without it where it does not.
"""

from __future__ import annotations

import numpy as np
import pytest

from modelgen.derivation.symbolic import derive
from modelgen.errors import ModelError
from modelgen.model.loading import builtin_model_path, load_model_text

NAV = builtin_model_path("ins_gnss21_nav").read_text()
WHOLE = "approximations: [lever_arm_at_computed_position, constant_radii, gravity_height_only, free_air_gradient]"
SCOPED = NAV.replace(WHOLE, "approximations: [lever_arm_at_computed_position, {name: constant_radii, in: [velocity, attitude]}, gravity_height_only, free_air_gradient]")
WITHOUT = NAV.replace(WHOLE, "approximations: [lever_arm_at_computed_position, gravity_height_only, free_air_gradient]")


def _numbers(text, name):
    model = load_model_text(text, filename=f"{name}.yaml")
    values = {**dict(model.parameter_defaults()), **model.check.parameter_values()}
    return model, derive(model).numeric(values)


def test_a_scoped_approximation_applies_to_its_rows_only_exactly(derived_builtin):
    whole_model = derived_builtin("ins_gnss21_nav").model
    whole = derived_builtin("ins_gnss21_nav").numeric({**dict(whole_model.parameter_defaults()), **whole_model.check.parameter_values()})
    scoped_model, scoped = _numbers(SCOPED, "scoped")
    _, without = _numbers(WITHOUT, "without")
    names = [s.name for s in scoped_model.states]
    position = [i for i, n in enumerate(names) if n.startswith("position_error")]
    others = [i for i in range(len(names)) if i not in position]
    assert np.array_equal(scoped["F"][others], whole["F"][others])  # the textbook's rows, exactly
    assert np.array_equal(scoped["F"][position], without["F"][position])  # dR/dL kept in the position rows
    assert np.abs(scoped["F"][position] - whole["F"][position]).max() > 0  # ... where the textbook drops it
    assert np.array_equal(scoped["G"], whole["G"])
    assert np.array_equal(scoped["H"], without["H"])  # measurements are not in its scope: their dR/dL terms stay
    assert not np.array_equal(scoped["H"], whole["H"])


def test_the_scoped_approximation_lists_only_the_terms_of_its_rows_and_says_where():
    model = load_model_text(SCOPED, filename="scoped.yaml")
    rows = {t.row for t in model.neglected if t.approximation == "constant_radii" and t.matrix == "F"}
    names = [s.name for s in model.states]
    assert rows and not any(names[r].startswith("position_error") for r in rows)
    assert any("constant_radii" in n and "in the velocity, attitude rows only" in n for n in model.notes)


@pytest.mark.parametrize(
    "entry, message",
    [
        ("{name: constant_radii, in: [wings]}", "navigation.approximations[0].in 'wings' is not one of attitude, velocity, position, measurements"),
        ("{name: no_vertical_channel, in: [velocity]}", "changes the model's states and cannot be scoped"),
        ("{name: no_earth_rate_position_terms, in: [velocity]}", "changes the perturbed equations and cannot be scoped"),
        ("{name: constant_radii}", "has no 'in'"),
    ],
)
def test_a_bad_scope_is_refused_with_file_line(entry, message):
    text = NAV.replace(WHOLE, f"approximations: [{entry}]")
    with pytest.raises(ModelError, match=r"^m\.yaml:\d+: ") as caught:
        load_model_text(text, filename="m.yaml")
    assert message in str(caught.value)
