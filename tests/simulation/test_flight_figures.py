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
