"""Shared fixtures of the export tests: enu_doppler18 derived once, with its check scenario's parameter values."""

from __future__ import annotations

import pytest

from modelgen.derivation.symbolic import derive
from modelgen.model.loading import load_model


@pytest.fixture(scope="session")
def enu_derived():
    return derive(load_model("enu_doppler18"))


@pytest.fixture(scope="session")
def enu_values(enu_derived):
    return enu_derived.model.check.parameter_values()
