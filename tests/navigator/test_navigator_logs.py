"""The text logs (IMU CSV, RTKLIB .pos), the checks every format shares, and the trajectory writers."""

from __future__ import annotations

import gzip
import math
import zlib

import numpy as np
import pytest

from modelgen.errors import ModelError
from modelgen.navigator.logs import ImuColumns, ImuGap, check_logs, read_imu_csv, read_rtklib_pos

COLUMNS = ImuColumns(count=11, time=1, accel=(2, 3, 4), gyro=(5, 6, 7), accel_unit="g", gyro_unit="rad/s")
POS_COLUMNS = ("latitude(deg) longitude(deg) height(m) Q ns sdn sde sdu sdne sdeu sdun age ratio "
               "vn(m/s) ve(m/s) vu(m/s) sdvn sdve sdvu sdvne sdveu sdvun\n")
POS_HEADER = "%  GPST  " + POS_COLUMNS


def imu_row(t: float, fz: float = 1.0) -> str:
    return f"{t:.3f},0.0,0.0,{fz},0.001,0.002,0.003,0,0,0,0\n"


def pos_row(second: float, lat: float = 40.0, q: int = 1, minute: int = 34) -> str:
    return (f"2025/07/08 19:{minute:02d}:{second:06.3f} {lat:.7f} -105.1 1601.0 {q} 21 0.01 0.01 0.01 0 0 0 0 0 "
            "1.0 2.0 -0.5 0.05 0.05 0.05 0 0 0\n")


# --- IMU CSV ---------------------------------------------------------------------------------------------------

def test_imu_csv_is_read_in_si_units_plain_and_gzipped(tmp_path):
    text = "".join(imu_row(100 + 0.01 * k) for k in range(5))
    (tmp_path / "imu.csv").write_text(text)
    (tmp_path / "imu.csv.gz").write_bytes(gzip.compress(text.encode()))
    for name in ("imu.csv", "imu.csv.gz"):
        log = read_imu_csv(tmp_path / name, COLUMNS)
        assert log.time.shape == (5,)
        assert log.specific_force[0, 2] == pytest.approx(9.80665)  # g -> m/s^2
        assert log.angular_rate[0].tolist() == [0.001, 0.002, 0.003]
        assert log.where(2) == f"{tmp_path / name}:3"


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


def test_imu_nan_rows_are_dropped_and_noted(tmp_path):
    path = tmp_path / "imu.csv"
    rows = [imu_row(1.0 + 0.01 * k) for k in range(10)]
    rows[4] = "1.04,nan,0,1,0,0,0,0,0,0,0\n"
    path.write_text("".join(rows))
    log = read_imu_csv(path, COLUMNS, gap_factor=3.0)
    assert len(log.time) == 9 and log.gaps == []  # the 0.02 s left by one dropped row is not a gap at factor 3
    assert any("1 row(s) with NaN" in note and "lines 5" in note for note in log.notes)


def test_imu_csv_in_utc_is_put_on_gps_time(tmp_path):
    path = tmp_path / "imu.csv"
    path.write_text(imu_row(1751998000.0) + imu_row(1751998000.01))
    gps = read_imu_csv(path, COLUMNS, time_system="GPST").time
    utc = read_imu_csv(path, COLUMNS, time_system="UTC").time
    assert (utc - gps).tolist() == [18.0, 18.0]


def test_imu_empty_file_and_bad_gzip_are_refused(tmp_path):
    (tmp_path / "empty.csv").write_text("\n")
    with pytest.raises(ModelError, match=r"empty\.csv: no IMU samples"):
        read_imu_csv(tmp_path / "empty.csv", COLUMNS)
    (tmp_path / "bad.csv.gz").write_bytes(b"\x1f\x8b" + b"not really gzip")
    with pytest.raises(ModelError, match=r"bad\.csv\.gz: is not a valid gzip file"):
        read_imu_csv(tmp_path / "bad.csv.gz", COLUMNS)
    (tmp_path / "cut.csv.gz").write_bytes(gzip.compress(imu_row(1.0).encode() * 100)[:-12])
    with pytest.raises(ModelError, match=r"cut\.csv\.gz: is not a valid gzip file"):
        read_imu_csv(tmp_path / "cut.csv.gz", COLUMNS)


def test_a_gzip_bomb_and_an_oversized_file_are_refused_before_they_fill_memory(tmp_path):
    from modelgen.navigator.logs.files import read_bytes

    bomb = tmp_path / "bomb.csv.gz"
    compressor = zlib.compressobj(9, zlib.DEFLATED, 16 + zlib.MAX_WBITS)
    bomb.write_bytes(compressor.compress(bytes(64 * 1024**2)) + compressor.flush())  # 64 MiB of zeros in ~64 kB
    assert bomb.stat().st_size < 200_000
    with pytest.raises(ModelError, match=r"bomb\.csv\.gz: expands beyond the 16 MiB a log may have"):
        read_bytes(bomb, limit=16 * 1024**2)
    with pytest.raises(ModelError, match=r"bomb\.csv\.gz: \d+ bytes is larger than the 1000 bytes a log may have"):
        read_bytes(bomb, limit=1000)


def test_imu_unknown_unit_is_refused():
    with pytest.raises(ModelError, match="accelerometer unit 'furlong' unknown"):
        read_imu_csv("x.csv", ImuColumns(11, 1, (2, 3, 4), (5, 6, 7), "furlong", "rad/s"))


# --- IMU gaps: refused by default, handed to the navigator when the configuration allows ------------------------

def _gap_log(tmp_path):
    path = tmp_path / "imu.csv"
    path.write_text("".join(imu_row(100.0 + 0.01 * k) for k in range(100))
                    + "".join(imu_row(105.99 + 0.01 * k) for k in range(100)))  # 5 s without samples after 100.99
    return path


def test_an_imu_gap_is_refused_by_default_naming_the_line_time_and_length(tmp_path):
    with pytest.raises(ModelError, match=r"imu\.csv:101: IMU gap of 5\.000 s after t = 100\.990 s \(longer than "
                                         r"imu\.gap_factor 3 x the median interval 0\.0100 s\); 1 gap\(s\).*"
                                         r"gap_action: propagate"):
        read_imu_csv(_gap_log(tmp_path), COLUMNS, gap_factor=3.0)


def test_a_propagated_imu_gap_is_listed_and_noted(tmp_path):
    log = read_imu_csv(_gap_log(tmp_path), COLUMNS, gap_factor=3.0, gap_action="propagate")
    assert len(log.gaps) == 1 and isinstance(log.gaps[0], ImuGap)
    assert log.gaps[0].start == pytest.approx(100.99) and log.gaps[0].length == pytest.approx(5.0)
    assert log.gaps[0].end == pytest.approx(105.99)
    assert any("IMU gap of 5.000 s after t = 100.990 s: propagated across" in note for note in log.notes)


def test_gnss_epochs_inside_a_propagated_gap_are_not_stacked_on_the_first_sample_after_it(tmp_path):
    """19 epochs of 4 Hz GNSS fall in the 5 s gap: prepare drops them (noted) instead of applying them all at once."""
    import calendar

    from modelgen.navigator.config import builtin_config_path, load_config
    from modelgen.navigator.navigator import prepare

    config = load_config(builtin_config_path())
    base = calendar.timegm((2025, 7, 8, 19, 34, 0, 0, 0, 0))
    imu_path = tmp_path / "imu.csv"
    imu_path.write_text("".join(imu_row(base + 0.01 * k) for k in range(1000))
                        + "".join(imu_row(base + 15.0 + 0.01 * k) for k in range(1000)))  # 5 s gap after 9.99 s
    (tmp_path / "gnss.pos").write_text(POS_HEADER + "".join(pos_row(0.5 + 0.25 * k) for k in range(90)))
    imu = read_imu_csv(imu_path, COLUMNS, gap_factor=3.0, gap_action="propagate")
    inputs = prepare(config, imu, read_rtklib_pos(tmp_path / "gnss.pos"))
    shifted_gap = (imu.gaps[0].start + config.time_offset, imu.gaps[0].end + config.time_offset)
    assert not ((inputs.gnss.time > shifted_gap[0]) & (inputs.gnss.time < shifted_gap[1])).any()
    assert any("GNSS epoch(s) inside IMU gaps not used" in note and note.split(": ")[1].startswith("20")
               for note in inputs.notes)
    targets = np.searchsorted(inputs.time, inputs.gnss.time)
    assert np.bincount(targets).max() == 1  # no IMU sample receives more than one epoch


# --- RTKLIB .pos -----------------------------------------------------------------------------------------------

def test_rtklib_pos_is_read_with_velocities_down_positive(tmp_path):
    path = tmp_path / "gnss.pos"
    path.write_text(POS_HEADER + pos_row(18.5) + pos_row(18.75))
    log = read_rtklib_pos(path)
    assert log.time[1] - log.time[0] == pytest.approx(0.25)
    assert log.latitude[0] == pytest.approx(math.radians(40.0))
    assert log.velocity[0].tolist() == [1.0, 2.0, 0.5]  # vn, ve, vd
    assert log.quality.tolist() == [1, 1]


def test_pos_time_is_read_to_the_nanosecond_on_one_rounding(tmp_path):
    path = tmp_path / "gnss.pos"
    path.write_text(POS_HEADER + pos_row(18.499) + pos_row(18.749))
    import calendar

    whole = calendar.timegm((2025, 7, 8, 19, 34, 0, 0, 0, 0))
    assert read_rtklib_pos(path).time.tolist() == [(whole * 10**9 + 18_499_000_000) / 10**9,
                                                  (whole * 10**9 + 18_749_000_000) / 10**9]


def test_a_utc_pos_is_put_on_gps_time_with_the_leap_seconds_of_its_date(tmp_path):
    gpst, utc, jst = (tmp_path / f"{n}.pos" for n in ("gpst", "utc", "jst"))
    gpst.write_text(POS_HEADER + pos_row(18.5))
    utc.write_text("%  UTC  " + POS_COLUMNS + pos_row(18.5))
    jst.write_text("%  JST  " + POS_COLUMNS + pos_row(18.5).replace("2025/07/08 19:", "2025/07/09 04:"))
    reference = read_rtklib_pos(gpst).time[0]
    assert read_rtklib_pos(utc).time[0] - reference == 18.0  # GPS - UTC = 18 s since 2017-01-01
    assert read_rtklib_pos(jst).time[0] - reference == 18.0
    assert any("UTC (column header) put on GPS time" in note for note in read_rtklib_pos(utc).notes)
    old = tmp_path / "old.pos"
    old.write_text("%  UTC  " + POS_COLUMNS + pos_row(18.5).replace("2025/07/08", "2016/12/31"))
    gps_old = tmp_path / "gps_old.pos"
    gps_old.write_text(POS_HEADER + pos_row(18.5).replace("2025/07/08", "2016/12/31"))
    assert read_rtklib_pos(old).time[0] - read_rtklib_pos(gps_old).time[0] == 17.0  # before the 2017 leap second


def test_unknown_time_systems_and_times_before_the_gps_epoch_are_refused(tmp_path):
    path = tmp_path / "gnss.pos"
    path.write_text("%  TAI  " + POS_COLUMNS + pos_row(18.5))
    with pytest.raises(ModelError, match=r"gnss\.pos:1: time system 'TAI' in the column header is not one of"):
        read_rtklib_pos(path)
    path.write_text("%  UTC  " + POS_COLUMNS + pos_row(18.5).replace("2025/07/08", "1979/07/08"))
    with pytest.raises(ModelError, match=r"before the GPS epoch 1980-01-06"):
        read_rtklib_pos(path)


def test_a_date_after_the_leap_table_is_converted_with_its_last_value_and_noted(tmp_path):
    path = tmp_path / "gnss.pos"
    path.write_text("%  UTC  " + POS_COLUMNS + pos_row(18.5).replace("2025/07/08", "2031/07/08"))
    log = read_rtklib_pos(path)
    assert any("after 2026-06-30" in note and "GPS - UTC = 18 s" in note for note in log.notes)


@pytest.mark.parametrize("word", ["e-baseline(m)", "n-baseline(m)"])
def test_a_baseline_pos_is_refused_never_read_as_degrees(tmp_path, word):
    path = tmp_path / "gnss.pos"
    path.write_text(f"%  GPST  {word} x(m) y(m) Q ns sde sdn sdu sden sdnu sdue age ratio\n"
                    "2025/07/08 19:34:18.500 12.3 -4.5 0.3 1 21 0.01 0.01 0.01 0 0 0 0 0\n")
    with pytest.raises(ModelError, match=r"gnss\.pos:1: (ENU|NED)-baseline solution .* not a position on the Earth"):
        read_rtklib_pos(path)


def test_a_pos_without_a_column_header_is_refused(tmp_path):
    path = tmp_path / "gnss.pos"
    path.write_text("% program : RTKPOST\n" + pos_row(18.5))
    with pytest.raises(ModelError, match=r"gnss\.pos:2: solution row before RTKLIB's column header"):
        read_rtklib_pos(path)


def test_an_ecef_pos_is_converted_to_latitude_longitude_height_and_ned(tmp_path):
    from modelgen.simulation.earth import geodetic_to_ecef, ned_to_ecef_matrix

    lat, lon, h = math.radians(40.0966268), math.radians(-105.1474483), 1601.474
    x = geodetic_to_ecef(lat, lon, h)
    c_en = ned_to_ecef_matrix(lat, lon)
    v = c_en @ np.array([1.0, 2.0, 0.5])  # NED velocity in ECEF
    cov_ned = np.diag([0.02**2, 0.03**2, 0.05**2])
    cov = c_en @ cov_ned @ c_en.T
    sd = [math.sqrt(cov[0, 0]), math.sqrt(cov[1, 1]), math.sqrt(cov[2, 2])]
    cross = [math.copysign(math.sqrt(abs(cov[i, j])), cov[i, j]) for i, j in ((0, 1), (1, 2), (2, 0))]
    row = " ".join(f"{value:.6f}" for value in (*x, 1, 21, *sd, *cross, 0, 0, *v, *sd, *cross))
    path = tmp_path / "gnss.pos"
    path.write_text("%  GPST  x-ecef(m) y-ecef(m) z-ecef(m) Q ns sdx(m) sdy(m) sdz(m) sdxy(m) sdyz(m) sdzx(m) "
                    "age(s) ratio vx(m/s) vy(m/s) vz(m/s) sdvx sdvy sdvz sdvxy sdvyz sdvzx\n"
                    f"2025/07/08 19:34:18.500 {row}\n")
    log = read_rtklib_pos(path)
    assert log.latitude[0] == pytest.approx(lat, abs=1e-9) and log.longitude[0] == pytest.approx(lon, abs=1e-9)
    assert log.height[0] == pytest.approx(h, abs=1e-4)
    assert np.allclose(log.velocity[0], [1.0, 2.0, 0.5], atol=1e-5)
    assert np.allclose(log.sigma_position[0], [0.02, 0.03, 0.05], atol=1e-5)
    assert np.allclose(log.sigma_velocity[0], [0.02, 0.03, 0.05], atol=1e-5)


def test_degree_minute_second_and_week_time_of_week_rows_are_read(tmp_path):
    reference = tmp_path / "deg.pos"
    reference.write_text(POS_HEADER + pos_row(18.5, lat=40.0966268))
    dms = tmp_path / "dms.pos"
    dms.write_text("%  GPST  latitude(d'\") longitude(d'\") height(m) Q ns sdn sde sdu sdne sdeu sdun age ratio\n"
                   "2025/07/08 19:34:18.500  40 05 47.85648 -105 06 00.00000 1601.0 1 21 0.01 0.01 0.01 0 0 0 0 0\n")
    log = read_rtklib_pos(dms)
    assert math.degrees(log.latitude[0]) == pytest.approx(40.0966268, abs=1e-9)
    assert math.degrees(log.longitude[0]) == pytest.approx(-105.1, abs=1e-9)
    week = tmp_path / "week.pos"
    week.write_text(POS_HEADER + pos_row(18.5, lat=40.0966268).replace("2025/07/08 19:34:18.500", "2374 243258.500"))
    assert read_rtklib_pos(week).time[0] == read_rtklib_pos(reference).time[0]


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
    path.write_text(POS_HEADER + pos_row(18.5).replace("2025/07/08 19:34:18.500", "1234 5678.0x"))
    with pytest.raises(ModelError, match=r"gnss\.pos:2: expected 'YYYY/MM/DD hh:mm:ss.sss' or GPS week"):
        read_rtklib_pos(path)


# --- GNSS that cannot align anything: each case its own true message ---------------------------------------------

def _imu(tmp_path, start: float = 0.0):
    import calendar

    base = calendar.timegm((2025, 7, 8, 19, 34, 0, 0, 0, 0)) + start
    path = tmp_path / "imu.csv"
    path.write_text("".join(imu_row(base + 0.01 * k) for k in range(3000)))
    return read_imu_csv(path, COLUMNS)


def test_a_pos_without_any_fix_says_so(tmp_path):
    path = tmp_path / "gnss.pos"
    path.write_text(POS_HEADER + "".join(pos_row(1.0 + 0.25 * k, q=0) for k in range(20)))
    gnss = read_rtklib_pos(path)
    assert len(gnss.time) == 0 and "20 epoch(s) with Q = 0 (no solution) dropped" in gnss.notes[0]
    with pytest.raises(ModelError, match=r"gnss\.pos: no GNSS fix at all"):
        check_logs(_imu(tmp_path), gnss, {1: 1.0}, 0.0)


def test_gnss_outside_the_imu_span_or_of_unused_quality_says_so(tmp_path):
    path = tmp_path / "gnss.pos"
    path.write_text(POS_HEADER + "".join(pos_row(1.0 + 0.25 * k, q=5) for k in range(20)))
    with pytest.raises(ModelError, match=r"no GNSS epoch inside the IMU span has a quality the configuration uses "
                                         r"\(gnss\.quality_factor: Q 1, 2; the log has Q 5 \(single\)\)"):
        check_logs(_imu(tmp_path), read_rtklib_pos(path), {1: 1.0, 2: 3.0}, 0.0)
    with pytest.raises(ModelError, match=r"no GNSS epoch inside the IMU log's time span"):
        check_logs(_imu(tmp_path, start=600.0), read_rtklib_pos(path), {5: 1.0}, 0.0)


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


# --- the trajectory writers ------------------------------------------------------------------------------------

def _flight(times):
    from modelgen.navigator.navigator import OUTPUT_FIELDS, Flight

    outputs = np.zeros((len(times), len(OUTPUT_FIELDS)))
    column = {n: i for i, n in enumerate(OUTPUT_FIELDS)}
    outputs[:, column["time"]] = times
    outputs[:, column["latitude"]] = math.radians(40.0966268)
    outputs[:, column["longitude"]] = math.radians(-105.1474483)
    outputs[:, column["height"]] = 1601.5
    outputs[:, column["v_north"]] = 1.5
    outputs[:, column["v_down"]] = -0.25
    outputs[:, column["sigma_north"]], outputs[:, column["sigma_east"]], outputs[:, column["sigma_up"]] = 0.12, 0.34, 0.56
    outputs[:, column["gnss_used"]] = 1
    outputs[:, column["gnss_quality"]] = 1
    outputs[:, column["cov_north_east"]], outputs[:, column["cov_east_up"]] = -0.0144, 0.0025
    return Flight(outputs, [], float(times[0]), float(times[0]))


def test_the_pos_output_carries_the_filter_sigmas_at_millisecond_times_and_reads_back(tmp_path):
    from modelgen.navigator.config import builtin_config_path, load_config
    from modelgen.navigator.report import pos_text

    times = 1752003261.0 + np.array([0.123, 0.373, 0.6234])
    text = pos_text(_flight(times), load_config(builtin_config_path()))
    assert "2025/07/08 19:34:21.123" in text and "19:34:21.373" in text and "19:34:21.623" in text
    assert "sdne, sdeu, sdun = its cross covariances (signed square roots)" in text
    row = next(line for line in text.splitlines() if not line.startswith("%")).split()
    assert row[10:13] == ["-0.1200", "0.0500", "0.0000"]  # sdne, sdeu, sdun: the flight's cross covariances
    (tmp_path / "out.pos").write_text(text)
    back = read_rtklib_pos(tmp_path / "out.pos")
    assert np.allclose(back.time, np.round(times, 3), atol=1e-6)
    assert back.sigma_position[0].tolist() == [0.12, 0.34, 0.56]
    assert math.degrees(back.latitude[0]) == pytest.approx(40.0966268, abs=1e-9)


def test_the_csv_trajectory_keeps_milliseconds(tmp_path):
    from modelgen.navigator.metrics import Errors
    from modelgen.navigator.report import csv_text

    times = 1752003261.0 + np.array([0.123, 0.373])
    zeros = np.zeros(2)
    errors = Errors(*[zeros] * len(Errors.__dataclass_fields__))
    rows = csv_text(_flight(times), errors).splitlines()
    assert rows[1].split(",")[0] == "1752003261.123" and rows[2].split(",")[0] == "1752003261.373"
    assert rows[1].split(",")[1] == "40.096626800"
