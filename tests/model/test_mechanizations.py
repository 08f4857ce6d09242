"""The mechanization seam (issue 27): one protocol, selected by navigation.mechanization."""

from __future__ import annotations

import pytest

from modelgen.errors import ModelError
from modelgen.model.mechanizations import MECHANIZATIONS, Mechanization, mechanization_named
from modelgen.model.mechanizations.local_level import LocalLevel
from modelgen.model.perturbation import problem


def test_local_level_is_registered_and_is_the_engines_default():
    assert MECHANIZATIONS["local_level"] is LocalLevel
    assert problem.Mechanization is LocalLevel
    assert problem.NavigationProblem.__dataclass_fields__["mechanization_name"].default == "local_level"


@pytest.mark.parametrize("name", sorted(MECHANIZATIONS))
def test_every_mechanization_satisfies_the_protocol(name):
    for method in ("earth_rate", "transport_rate", "navigation_rate", "velocity_rate", "position_rate", "gravity",
                   "error_frame_angle", "metres", "metres_inverse"):
        assert callable(getattr(MECHANIZATIONS[name], method)), method
        assert method in Mechanization.__dict__, method


def test_an_unknown_mechanization_is_refused_naming_the_known_ones():
    with pytest.raises(ModelError, match="unknown mechanization 'ecef2' \\(known: ecef, local_level, wander_azimuth\\)"):
        mechanization_named("ecef2", "m.yaml:3: navigation.mechanization")
