"""Shared fixtures of the export tests: enu_doppler18 derived once, with its check scenario's parameter values."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def enu_derived(derived_builtin):
    return derived_builtin("enu_doppler18")


@pytest.fixture(scope="session")
def enu_values(enu_derived):
    return enu_derived.model.check.parameter_values()
