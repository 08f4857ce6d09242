"""The alignment on awkward logs: outages hide its epochs, and each way it cannot align has its own message.

The 60 s excerpt of the drive aligns at 13.75 s (heading epoch) from a rest window ending before it; these tests
cut, slow down or hide parts of it and check what the alignment (Python rules; the C navigator reports the same
diagnosis) takes or says.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from modelgen.errors import ModelError
from modelgen.navigator.alignment import align
from modelgen.navigator.outages import in_outage, outage_windows

pytestmark = pytest.mark.flight

DATA = Path(__file__).parent / "data"


def _excerpt():
    from modelgen.navigator.config import load_config
    from modelgen.navigator.logs import read_imu_csv, read_rtklib_pos
    from modelgen.navigator.navigator import prepare

    config = load_config(DATA / "excerpt.yaml")
    return config, prepare(config, read_imu_csv(config.imu_file, config.imu_columns, config.gap_factor),
                           read_rtklib_pos(config.gnss_file))


def _gnss_where(g, keep: np.ndarray, velocity: np.ndarray | None = None):
    return replace(g, time=g.time[keep], latitude=g.latitude[keep], longitude=g.longitude[keep], height=g.height[keep],
                   quality=g.quality[keep], satellites=g.satellites[keep], sigma_position=g.sigma_position[keep],
                   velocity=(g.velocity if velocity is None else velocity)[keep], sigma_velocity=g.sigma_velocity[keep])


def _cut(inputs, end_s: float):
    """The log (IMU and GNSS, the GNSS as read too) up to ``end_s`` after its first epoch."""
    end = inputs.first_epoch + end_s
    imu = inputs.time <= end
    g = _gnss_where(inputs.gnss, inputs.gnss.time <= end)
    return replace(inputs, time=inputs.time[imu], force=inputs.force[imu], rate=inputs.rate[imu], gnss=g, source_gnss=g)


def test_an_outage_over_the_heading_epoch_moves_the_alignment_to_the_first_used_epoch_after_it():
    """The excerpt's heading epoch (13.75 s) and its neighbours hidden by an outage: the alignment uses none of
    them (issue 26: 'the alignment uses a GNSS fix hidden by an outage'), but the first fast epoch after it."""
    config, inputs = _excerpt()
    free = align(config, inputs)
    start = free.time - inputs.first_epoch - 1.0
    hidden = replace(config, outage_schedule=None, outage_windows=[(start, 4.0)])
    windows = outage_windows(None, hidden.outage_windows, inputs.first_epoch, float(inputs.gnss.time[-1]))
    outage = in_outage(inputs.gnss.time, windows)
    assert outage[free.epoch]  # the free alignment's heading epoch is hidden
    moved = align(hidden, inputs)
    assert moved.time > free.time and moved.time >= windows[0][1]
    assert not outage[moved.epoch]
    assert not in_outage(np.array([moved.rest_end]), windows)[0]  # nor is the rest epoch


def test_fast_epochs_all_inside_outages_say_so():
    config, inputs = _excerpt()
    free = align(config, inputs)
    start = free.time - inputs.first_epoch - 1.0
    hidden = replace(config, outage_schedule=None, outage_windows=[(start, 1000.0)])
    with pytest.raises(ModelError, match="lies inside a simulated outage .*used for nothing, the alignment included"):
        align(hidden, inputs)


def test_a_log_that_ends_at_rest_says_it_ends_before_the_alignment_not_that_the_vehicle_never_moves():
    config, inputs = _excerpt()
    short = _cut(inputs, 8.0)  # the excerpt is at rest for its first 12 s
    with pytest.raises(ModelError) as refused:
        align(config, short)
    message = str(refused.value)
    assert "the log ends at 8.00 s with the vehicle still at rest" in message
    assert "it ends before the alignment" in message
    assert "never moves" not in message


def test_a_vehicle_that_moves_but_never_as_fast_as_the_heading_speed_says_so():
    config, inputs = _excerpt()
    g = inputs.gnss
    speed = np.hypot(g.velocity[:, 0], g.velocity[:, 1])
    cap = 0.5 * config.heading_speed  # faster than rest_speed, slower than heading_speed
    assert cap > config.rest_speed
    slow = g.velocity * np.minimum(1.0, cap / np.maximum(speed, 1e-9))[:, None]
    crawling = replace(inputs, gnss=_gnss_where(g, np.ones(len(g.time), bool), slow), source_gnss=None)
    with pytest.raises(ModelError, match=r"the vehicle never moves faster than alignment\.heading_speed_m_s = "
                                         r"\S+ m/s in the log \(fastest used GNSS epoch 0\.\d+ m/s"):
        align(config, crawling)


def test_an_imu_log_that_ends_before_the_first_fast_gnss_epoch_says_the_log_ends_before_the_alignment():
    config, inputs = _excerpt()
    end = inputs.first_epoch + 8.0
    imu = inputs.time <= end
    short_imu = replace(inputs, time=inputs.time[imu], force=inputs.force[imu], rate=inputs.rate[imu],
                        gnss=_gnss_where(inputs.gnss, inputs.gnss.time <= end))  # source_gnss: the whole log
    with pytest.raises(ModelError, match=r"the IMU log ends at 8\.00 s .* the log ends before the alignment"):
        align(config, short_imu)


def test_a_gnss_log_without_any_fix_is_refused_as_such_before_the_alignment(tmp_path):
    from modelgen.navigator.logs import check_logs, read_imu_csv, read_rtklib_pos

    config, _ = _excerpt()
    lines = (DATA / "excerpt.pos").read_text().splitlines()
    rows = [line if line.startswith("%") else _with_quality(line, 0) for line in lines]
    (tmp_path / "nofix.pos").write_text("\n".join(rows) + "\n")
    gnss = read_rtklib_pos(tmp_path / "nofix.pos")
    imu = read_imu_csv(config.imu_file, config.imu_columns, config.gap_factor)
    with pytest.raises(ModelError, match="no GNSS fix at all") as refused:
        check_logs(imu, gnss, config.quality_factor, config.time_offset)
    assert "never moves" not in str(refused.value)


def _with_quality(line: str, q: int) -> str:
    fields = line.split()
    fields[5] = str(q)
    return " ".join(fields)


@pytest.mark.compile
def test_the_c_navigator_also_skips_the_hidden_heading_epoch():
    """The C aligns itself from the per-epoch use flags: the same epoch and angles as the Python rules."""
    from modelgen.navigator.cnav import cached_c_navigator, fly_c, log_arrays
    from modelgen.navigator.errorstate import model_path
    from modelgen.navigator.spec import navigator_spec

    config, inputs = _excerpt()
    free = align(config, inputs)
    hidden = replace(config, outage_schedule=None, outage_windows=[(free.time - inputs.first_epoch - 1.0, 4.0)])
    python = align(hidden, inputs)
    spec = navigator_spec(model_path(config.model, config.path), with_python=False)
    navigator, _ = cached_c_navigator(spec, rest_max=log_arrays(hidden, inputs, spec).rest_max)
    flight, _ = fly_c(hidden, inputs, navigator)
    assert flight.alignment["time"] == python.time > free.time
    assert abs(flight.alignment["heading"] - python.heading) <= 1e-12


@pytest.mark.parametrize("window_s", [70.0, 1.0e4])
def test_a_still_window_longer_than_the_log_is_one_refusal_naming_its_configuration_line(tmp_path, window_s):
    """alignment.still_window_s longer than the whole IMU log (61 s): one 'modelgen: error:' line naming the
    configuration file and the key's line, exit 2, for either navigator, before any navigator is built.  Before:
    the alignment's diagnosis, naming the GNSS file and no configuration line (70 s: 7000 samples, inside the
    C's 8192-sample ring, so its bound passed it too)."""
    import yaml

    from cli_in_process import run_modelgen

    data = yaml.safe_load((DATA / "excerpt.yaml").read_text())
    for section in ("imu", "gnss"):
        data[section]["file"] = str(DATA / data[section]["file"])
    data["alignment"]["still_window_s"] = window_s
    path = tmp_path / "nav.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    line = next(i for i, text in enumerate(path.read_text().splitlines(), start=1) if "still_window_s:" in text)
    for navigator in ("c", "python"):
        result = run_modelgen(["replay", path, "--out", tmp_path / navigator, "--no-figures", "--navigator", navigator],
                              tmp_path, timeout=300)
        errors = [x for x in result.stderr.splitlines() if x.startswith("modelgen: error:")]
        assert result.returncode == 2 and len(errors) == 1, result.stderr
        assert errors[0].startswith(f"modelgen: error: {path}:{line}: alignment.still_window_s: "), errors[0]
        assert "more than the whole IMU log has" in errors[0] and "Traceback" not in result.stderr
        assert not (tmp_path / navigator).exists()
