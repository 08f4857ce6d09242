"""The figures of `modelgen simulate` (modelgen.simulation.flight_figures): coinciding curves named, lines cut to their pixels."""

import numpy as np
import pytest


def test_coinciding_modes_names_a_curve_lying_on_an_earlier_one_only():
    from modelgen.simulation.flight_figures import coinciding_modes

    base = np.linspace(1.0, 2.0, 50)
    notes = coinciding_modes({"open_loop": base, "closed_loop": base * 1.5, "accumulated": base * 1.5 * (1 + 1e-6)})
    assert list(notes) == ["accumulated"]
    assert notes["accumulated"][0] == "closed_loop" and notes["accumulated"][1] < 1e-5


def test_pixel_envelope_keeps_each_pixel_columns_first_last_smallest_and_largest_sample():
    from modelgen.simulation.flight_figures import pixel_envelope

    rng = np.random.default_rng(3)
    values = np.cumsum(rng.standard_normal(10_000))
    values[1234] = np.nan
    columns = 97
    kept = pixel_envelope(values, columns)
    assert np.all(np.diff(kept) > 0) and len(kept) <= 4 * columns + 1
    assert 1234 in kept
    edges = np.linspace(0, len(values), columns + 1).round().astype(int)
    for start, stop in zip(edges[:-1], edges[1:]):
        run = values[start:stop]
        mine = values[kept[(kept >= start) & (kept < stop)]]
        assert start in kept and stop - 1 in kept
        assert np.nanmin(mine) == np.nanmin(run) and np.nanmax(mine) == np.nanmax(run)


def test_pixel_envelope_keeps_every_sample_of_a_short_series_and_refuses_no_columns():

    from modelgen.simulation.flight_figures import pixel_envelope

    assert list(pixel_envelope(np.arange(40.0), 10)) == list(range(40))
    with pytest.raises(ValueError, match="columns must be positive"):
        pixel_envelope(np.arange(40.0), 0)


def test_figures_show_angles_in_arcmin_positions_in_metres_drifts_in_deg_per_hour_and_biases_in_mg():
    import math

    from modelgen.simulation import earth
    from modelgen.simulation.flight_figures import display_factors, display_units

    units = {"tilt": "rad", "latitude_error": "rad", "longitude_error": "rad", "drift": "rad/s", "bias": "m/s^2",
             "speed": "m/s"}
    positions = {"latitude_error": "latitude", "longitude_error": "longitude"}
    assert display_units(units, positions) == {"tilt": "arcmin", "latitude_error": "m north", "longitude_error": "m east",
                                               "drift": "deg/h", "bias": "mg", "speed": "m/s"}
    latitude, height = math.radians(30.0), 3000.0
    factors = display_factors(units, positions, latitude, height)
    meridian, prime_vertical = earth.radii_of_curvature(latitude)
    assert factors["tilt"] == pytest.approx(180 * 60 / math.pi)
    assert factors["latitude_error"] == pytest.approx(meridian + height)
    assert factors["longitude_error"] == pytest.approx((prime_vertical + height) * math.cos(latitude))
    assert factors["drift"] == pytest.approx(180 * 3600 / math.pi) and factors["bias"] == pytest.approx(1e3 / 9.80665)
    assert factors["speed"] == 1.0


def test_the_nees_of_one_run_is_called_one_run_and_its_verdict_follows_the_criterion():
    from modelgen.simulation.flight_figures import nees_verdict
    from modelgen.simulation.montecarlo import NeesTest

    times = np.arange(10.0)
    one = NeesTest(times, np.full(10, 18.0), 8.2, 31.5, 18, 1, 0.95)
    assert nees_verdict(one).startswith("NEES of the one run inside the 95 % chi-square band at 100 % of the times")
    assert "ensemble" not in nees_verdict(one) and "consistent" not in nees_verdict(one)
    assert nees_verdict(one).endswith("(criterion: at least 85 %: met)")
    outside = NeesTest(times, np.r_[np.full(5, 18.0), np.full(5, 60.0)], 8.2, 31.5, 18, 16, 0.95)
    assert nees_verdict(outside).startswith("mean NEES over 16 runs") and nees_verdict(outside).endswith(": missed)")
