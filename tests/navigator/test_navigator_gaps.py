"""A propagated IMU gap (imu.gap_action: propagate) is flown honestly: the covariance grows over its whole length.

The excerpt of the drive with 5 s of IMU samples removed (32-37 s after its first GNSS epoch, while the car
drives) inside a 12-s GNSS outage (30-42 s): at the first epoch after the gap no GNSS is applied, so the recorded
sigma is the covariance propagated across the gap.  The same outage flown with every IMU sample is the reference.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

pytestmark = [pytest.mark.flight, pytest.mark.compile]

DATA = Path(__file__).parent / "data"


@pytest.fixture(scope="module")
def gap_flights():
    from modelgen.navigator.cnav import cached_c_navigator, fly_c
    from modelgen.navigator.config import load_config
    from modelgen.navigator.errorstate import model_path
    from modelgen.navigator.logs import read_imu_csv, read_rtklib_pos
    from modelgen.navigator.logs.checks import apply_gap_policy
    from modelgen.navigator.navigator import fly, prepare
    from modelgen.navigator.spec import navigator_spec

    config = load_config(DATA / "excerpt.yaml")
    imu = read_imu_csv(config.imu_file, config.imu_columns, config.gap_factor)
    gnss = read_rtklib_pos(config.gnss_file)
    first = float(gnss.time[0])
    config = replace(config, outage_schedule=None, outage_windows=[(30.0, 12.0)], gap_action="propagate")
    t = imu.time + config.time_offset
    cut = (t > first + 32.0) & (t < first + 37.0)
    gapped = replace(imu, time=imu.time[~cut], specific_force=imu.specific_force[~cut],
                     angular_rate=imu.angular_rate[~cut], records=imu.records[~cut], notes=[])
    gapped = apply_gap_policy(gapped, config.gap_factor, config.gap_action)
    assert len(gapped.gaps) == 1 and gapped.gaps[0].length == pytest.approx(5.0, abs=0.02)
    full, with_gap = prepare(config, imu, gnss), prepare(config, gapped, gnss)
    spec = navigator_spec(model_path(config.model, config.path))
    navigator, _ = cached_c_navigator(spec)
    flights = {"python": (fly(config, full, spec), fly(config, with_gap, spec)),
               "c": (fly_c(config, full, navigator)[0], fly_c(config, with_gap, navigator)[0])}
    return first, flights


def _sigma_h(flight, first: float, at: float) -> tuple[float, float]:
    """(output time after the first epoch, horizontal 1-sigma) of the output nearest ``at`` seconds."""
    from modelgen.navigator.navigator import OUTPUT_FIELDS

    column = {n: i for i, n in enumerate(OUTPUT_FIELDS)}
    i = int(np.argmin(np.abs(flight.outputs[:, 0] - first - at)))
    row = flight.outputs[i]
    return float(row[0] - first), float(np.hypot(row[column["sigma_north"]], row[column["sigma_east"]]))


@pytest.mark.parametrize("navigator", ["python", "c"])
def test_the_covariance_grows_over_a_propagated_gap_as_over_the_same_span_with_data(gap_flights, navigator):
    first, flights = gap_flights
    full, with_gap = flights[navigator]
    when_before, before = _sigma_h(with_gap, first, 31.9)  # the last epoch before the gap
    when_after, after = _sigma_h(with_gap, first, 37.25)  # the first epoch after it (inside the outage)
    _, reference = _sigma_h(full, first, 37.25)
    assert when_before < 32.0 and 37.0 < when_after < 37.5
    # Measured: 0.06 m before the gap, 0.485 m after it, 0.422 m at the same epoch with every IMU sample: the
    # covariance is propagated over the gap's 5 s (one nominal 0.1 s predict would leave it near 0.07 m).
    assert after > 5.0 * before
    assert after >= 0.95 * reference


def test_c_and_python_propagate_the_gap_alike(gap_flights):
    first, flights = gap_flights
    python, c = flights["python"][1], flights["c"][1]
    assert np.array_equal(python.outputs[:, 0], c.outputs[:, 0])
    assert _sigma_h(c, first, 37.25)[1] == pytest.approx(_sigma_h(python, first, 37.25)[1], rel=1e-9)


def test_no_output_epoch_falls_inside_the_gap(gap_flights):
    first, flights = gap_flights
    for flight in flights["python"][1], flights["c"][1]:
        since = flight.outputs[:, 0] - first
        assert not ((since > 32.0) & (since < 37.0)).any()
