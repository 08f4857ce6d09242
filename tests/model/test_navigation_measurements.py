"""Pseudo-range rates need the satellites' velocity, or say on purpose that they are still (issue 27)."""

from __future__ import annotations

import pytest

from modelgen.errors import ModelError
from modelgen.model.loading import load_model_text

RATE = """\
model: m
frame: NED
navigation:
  errors: {attitude: {form: phi}, velocity: {form: difference}, position: {form: metres}}
  sensor_errors:
    - {of: receiver_clock, process: clock, psd: [1.0e-2, 1.0e-3]}
  measurements:
    - {of: pseudorange_rate, symbols: [zd_1], variance: 0.01, line_of_sight: [[e_1_n, e_1_e, e_1_d]]SATELLITE}
"""


def test_a_range_rate_without_satellite_velocity_is_refused():
    with pytest.raises(ModelError, match="m.yaml:8: a pseudo-range rate needs 'satellite_velocity'"):
        load_model_text(RATE.replace("SATELLITE", ""), "m.yaml")


def test_still_satellites_on_purpose_give_the_rate_of_the_receivers_own_velocity():
    model = load_model_text(RATE.replace("SATELLITE", ", satellite_velocity: zero"), "m.yaml")
    moving = load_model_text(RATE.replace("SATELLITE", ", satellite_velocity: [[s_n, s_e, s_d]]"), "m.yaml")
    assert model.measurement_expressions["pseudorange_rate_difference_zd_1"] != moving.measurement_expressions["pseudorange_rate_difference_zd_1"]
