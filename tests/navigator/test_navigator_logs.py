"""The IMU CSV and RTKLIB .pos readers: what they read, what they refuse (file:line), what they handle."""

from __future__ import annotations

import gzip
import math

import numpy as np
import pytest

from modelgen.errors import ModelError
from modelgen.navigator.logs import ImuColumns, read_imu_csv, read_rtklib_pos

COLUMNS = ImuColumns(count=11, time=1, accel=(2, 3, 4), gyro=(5, 6, 7), accel_unit="g", gyro_unit="rad/s")
POS_HEADER = "%  GPST  latitude(deg) longitude(deg) height(m) Q ns sdn sde sdu sdne sdeu sdun age ratio vn ve vu sdvn sdve sdvu sdvne sdveu sdvun\n"


def imu_row(t: float, fz: float = 1.0) -> str:
    return f"{t:.3f},0.0,0.0,{fz},0.001,0.002,0.003,0,0,0,0\n"


def pos_row(second: float, lat: float = 40.0) -> str:
    return (f"2025/07/08 19:34:{second:06.3f} {lat:.7f} -105.1 1601.0 1 21 0.01 0.01 0.01 0 0 0 0 0 "
            "1.0 2.0 -0.5 0.05 0.05 0.05 0 0 0\n")


def test_imu_csv_is_read_in_si_units_plain_and_gzipped(tmp_path):
    text = "".join(imu_row(100 + 0.01 * k) for k in range(5))
    (tmp_path / "imu.csv").write_text(text)
    (tmp_path / "imu.csv.gz").write_bytes(gzip.compress(text.encode()))
    for name in ("imu.csv", "imu.csv.gz"):
        log = read_imu_csv(tmp_path / name, COLUMNS)
        assert log.time.shape == (5,)
        assert log.specific_force[0, 2] == pytest.approx(9.80665)  # g -> m/s^2
        assert log.angular_rate[0].tolist() == [0.001, 0.002, 0.003]


def test_imu_row_with_wrong_column_count_is_refused_with_its_line(tmp_path):
    path = tmp_path / "imu.csv"
    path.write_text(imu_row(1.0) + imu_row(1.01) + "1.02,0,0,1,0,0,0\n")
    with pytest.raises(ModelError, match=r"imu\.csv:3: 7 columns, expected 11"):
        read_imu_csv(path, COLUMNS)


def test_imu_duplicated_and_backward_time_stamps_are_refused_with_their_line(tmp_path):
    path = tmp_path / "imu.csv"
    path.write_text(imu_row(1.0) + imu_row(1.01) + imu_row(1.01))
    with pytest.raises(ModelError, match=r"imu\.csv:3: time stamp .* duplicated"):
        read_imu_csv(path, COLUMNS)
    path.write_text(imu_row(1.0) + imu_row(1.01) + imu_row(1.005))
    with pytest.raises(ModelError, match=r"imu\.csv:3: time stamp .* goes back"):
        read_imu_csv(path, COLUMNS)


def test_imu_non_numeric_field_is_refused_naming_line_and_column(tmp_path):
    path = tmp_path / "imu.csv"
    path.write_text(imu_row(1.0) + "1.01,0.0,abc,1,0,0,0,0,0,0,0\n")
    with pytest.raises(ModelError, match=r"imu\.csv:2: column 3 'abc' is not a number"):
        read_imu_csv(path, COLUMNS)


def test_imu_nan_rows_are_dropped_and_reported_and_gaps_are_reported(tmp_path):
    path = tmp_path / "imu.csv"
    rows = [imu_row(1.0 + 0.01 * k) for k in range(10)]
    rows[4] = "1.04,nan,0,1,0,0,0,0,0,0,0\n"
    rows += [imu_row(1.5 + 0.01 * k) for k in range(5)]  # a 0.41 s gap
    path.write_text("".join(rows))
    log = read_imu_csv(path, COLUMNS)
    assert len(log.time) == 14
    assert any("1 row(s) with NaN" in note and "lines 5" in note for note in log.notes)
    assert [round(length, 2) for _, length in log.gaps] == [0.41]
    assert any("gap of 0.410 s" in note and "bridged" in note for note in log.notes)


def test_imu_empty_file_and_bad_gzip_are_refused(tmp_path):
    (tmp_path / "empty.csv").write_text("\n")
    with pytest.raises(ModelError, match=r"empty\.csv: no IMU samples"):
        read_imu_csv(tmp_path / "empty.csv", COLUMNS)
    (tmp_path / "bad.csv.gz").write_bytes(b"\x1f\x8b" + b"not really gzip")
    with pytest.raises(ModelError, match=r"bad\.csv\.gz: is not a valid gzip file"):
        read_imu_csv(tmp_path / "bad.csv.gz", COLUMNS)


def test_imu_unknown_unit_is_refused():
    with pytest.raises(ModelError, match="accelerometer unit 'furlong' unknown"):
        read_imu_csv("x.csv", ImuColumns(11, 1, (2, 3, 4), (5, 6, 7), "furlong", "rad/s"))


def test_rtklib_pos_is_read_with_velocities_down_positive(tmp_path):
    path = tmp_path / "gnss.pos"
    path.write_text(POS_HEADER + pos_row(18.5) + pos_row(18.75))
    log = read_rtklib_pos(path)
    assert log.time[1] - log.time[0] == pytest.approx(0.25)
    assert log.latitude[0] == pytest.approx(math.radians(40.0))
    assert log.velocity[0].tolist() == [1.0, 2.0, 0.5]  # vn, ve, vd
    assert log.quality.tolist() == [1, 1]


def test_rtklib_empty_and_header_only_files_are_refused(tmp_path):
    path = tmp_path / "gnss.pos"
    for text in ("", POS_HEADER):
        path.write_text(text)
        with pytest.raises(ModelError, match=r"gnss\.pos: no solution epochs \(empty or header-only"):
            read_rtklib_pos(path)


def test_rtklib_rows_that_are_short_non_numeric_or_out_of_order_are_refused_with_their_line(tmp_path):
    path = tmp_path / "gnss.pos"
    path.write_text(POS_HEADER + pos_row(18.5) + "2025/07/08 19:34:18.750 40.0 -105.1 1601.0\n")
    with pytest.raises(ModelError, match=r"gnss\.pos:3: 5 columns"):
        read_rtklib_pos(path)
    path.write_text(POS_HEADER + pos_row(18.5).replace("1601.0", "high"))
    with pytest.raises(ModelError, match=r"gnss\.pos:2: column 5 'high' is not a number"):
        read_rtklib_pos(path)
    path.write_text(POS_HEADER + pos_row(18.75) + pos_row(18.5))
    with pytest.raises(ModelError, match=r"gnss\.pos:3: epoch .* goes back in time"):
        read_rtklib_pos(path)
    path.write_text(POS_HEADER + pos_row(18.5) + pos_row(18.5))
    with pytest.raises(ModelError, match=r"gnss\.pos:3: epoch .* duplicated"):
        read_rtklib_pos(path)
    path.write_text(POS_HEADER + pos_row(18.5).replace("2025/07/08 19:34:18.500", "1234 5678.0"))
    with pytest.raises(ModelError, match=r"gnss\.pos:2: expected GPST"):
        read_rtklib_pos(path)


def test_gnss_epochs_before_the_first_imu_sample_are_dropped_and_noted(tmp_path):
    from modelgen.navigator.config import builtin_config_path, load_config
    from modelgen.navigator.navigator import prepare

    config = load_config(builtin_config_path())
    (tmp_path / "gnss.pos").write_text(POS_HEADER + "".join(pos_row(18.0 + 0.25 * k) for k in range(8)))
    gnss = read_rtklib_pos(tmp_path / "gnss.pos")
    imu_path = tmp_path / "imu.csv"
    start = gnss.time[3] + 0.125  # first IMU sample (after the -0.125 s offset) at the 4th epoch
    imu_path.write_text("".join(imu_row(start + 0.01 * k) for k in range(200)))
    inputs = prepare(config, read_imu_csv(imu_path, COLUMNS), gnss)
    assert np.allclose(inputs.gnss.time, gnss.time[3:])
    assert any("3 GNSS epoch(s) before the first IMU sample not used" in note for note in inputs.notes)
