"""Study files: what a valid one becomes, and every kind of bad input refused with file:line before any work."""

import textwrap

import pytest

from modelgen.errors import ModelError
from modelgen.study.studyfile import MAX_CASES, load_study

GRID = """\
study: small
parameters:
  gyro_drift:
    unit: deg/h
    values: [0.01, 0.1]
    sets: [gyro_markov_sigma_x, initial_sigma.gyro_constant_drift_x]
  doppler_noise:
    unit: m/s
    range: {from: 0.1, to: 0.4, count: 4}
    sets: [doppler_noise_sigma_north, doppler_noise_sigma_east]
filters: [optimal, suboptimal_2]
"""


def write(tmp_path, text: str):
    path = tmp_path / "study.yaml"
    path.write_text(textwrap.dedent(text), encoding="utf-8")
    return path


def refused(tmp_path, text: str) -> str:
    with pytest.raises(ModelError) as info:
        load_study(write(tmp_path, text))
    return str(info.value)


def test_a_grid_is_every_combination_of_the_parameter_values_with_every_filter(tmp_path):
    study = load_study(write(tmp_path, GRID))
    assert [p.name for p in study.parameters] == ["gyro_drift", "doppler_noise"]
    assert study.parameters[1].values == pytest.approx((0.1, 0.2, 0.3, 0.4))
    assert len(study.points) == 8 and study.case_count == 16
    assert study.points[0] == (0.01, 0.1) and study.points[-1] == pytest.approx((0.1, 0.4))
    assert [f.name for f in study.filters] == ["optimal", "suboptimal_2"]
    assert study.plot_x == "gyro_drift" and study.metric == "position_cep"


def test_a_log_range_is_geometric_and_marked_for_a_log_axis(tmp_path):
    study = load_study(write(tmp_path, GRID.replace("values: [0.01, 0.1]", "range: {from: 0.001, to: 1, count: 4, spacing: log}")))
    assert study.parameters[0].values == pytest.approx((0.001, 0.01, 0.1, 1.0))
    assert study.parameters[0].log_spaced and not study.parameters[1].log_spaced


def test_a_list_study_takes_its_cases_in_order(tmp_path):
    text = """\
    study: listed
    parameters:
      doppler_noise: {unit: km/h, sets: [doppler_noise_sigma_north]}
      latitude: {unit: deg, sets: [scenario.latitude]}
    cases:
      - {doppler_noise: 0.6, latitude: 45}
      - {doppler_noise: 1.2, latitude: -10}
    filters: [optimal, pure_inertial]
    """
    study = load_study(write(tmp_path, text))
    assert study.points == ((0.6, 45.0), (1.2, -10.0)) and study.case_count == 4


def test_filter_variants_are_paper_filters_with_changed_settings(tmp_path):
    text = GRID.replace("filters: [optimal, suboptimal_2]", """\
filters:
  optimal: {}
  sub2_n6: {like: suboptimal_2, manoeuvre_gain_period: 6}
  sub1_driving: {like: suboptimal_1, whitening: driving_noise}
""")
    study = load_study(write(tmp_path, text))
    variants = {f.name: f.design for f in study.filters}
    assert variants["sub2_n6"].gain_period == 6 and variants["sub2_n6"].manoeuvre_gain_period == 6
    assert variants["sub2_n6"].key == "sub2_n6"
    assert variants["sub1_driving"].whitening == "driving_noise" and variants["sub1_driving"].reduced


def test_the_shipped_study_has_one_thousand_covariance_cases_of_the_papers_model():
    study = load_study("paper_gyro_doppler_1000")
    assert study.case_count == 1000 and study.model.name == "ned_doppler18"
    assert study.monte_carlo is not None and study.monte_carlo.runs >= 2


@pytest.mark.parametrize(
    "change, fragments",
    [
        (("filters:", "filtres: [optimal]\nfilters:"), ["study.yaml:", "unknown key 'filtres'"]),
        (("gyro_markov_sigma_x,", "gyro_markov_sigma_w,"), ["study.yaml:6", "unknown parameter 'gyro_markov_sigma_w'"]),
        (("unit: deg/h", "unit: m/s"), ["study.yaml:4", "measures speed", "angular rate"]),
        (("unit: deg/h", "unit: furlong"), ["study.yaml:4", "not one of"]),
        (("values: [0.01, 0.1]", "values: []"), ["study.yaml:5", "empty grid"]),
        (("values: [0.01, 0.1]", "values: [0.01, -0.1]"), ["study.yaml:5", "cannot be negative"]),
        (("values: [0.01, 0.1]", "values: [0.01, .nan]"), ["study.yaml:5", "not finite"]),
        (("values: [0.01, 0.1]", "values: [0.01, ten]"), ["study.yaml:5", "not a number"]),
        (("count: 4", "count: 0"), ["study.yaml:9", "out of range"]),
        (("from: 0.1, to: 0.4, count: 4", "from: 0, to: 0.4, count: 4, spacing: log"), ["log-spaced range needs from > 0"]),
        (("filters: [optimal, suboptimal_2]", "filters: [optimal, suboptimal_9]"), ["study.yaml:11", "'suboptimal_9' is not one of"]),
        (("filters: [optimal, suboptimal_2]", "filters: []"), ["study.yaml:11", "empty list"]),
        (("filters: [optimal, suboptimal_2]", "filters: [optimal, optimal]"), ["named twice"]),
        (("count: 4", "count: 10001"), ["study.yaml:9", "out of range"]),
    ],
)
def test_bad_study_files_are_refused_with_the_line(tmp_path, change, fragments):
    old, new = change
    assert old in GRID
    message = refused(tmp_path, GRID.replace(old, new, 1))
    for fragment in fragments:
        assert fragment in message, message


def test_a_study_with_too_many_cases_is_refused_before_it_runs(tmp_path):
    text = GRID.replace("values: [0.01, 0.1]", "values: [1, 2, 3, 4, 5, 6]").replace("count: 4", "count: 10000")
    assert 6 * 10000 * 2 > MAX_CASES
    assert f"a study may have at most {MAX_CASES}" in refused(tmp_path, text)


def test_a_latitude_at_a_pole_is_out_of_range(tmp_path):
    text = """\
    study: polar
    parameters:
      latitude: {unit: deg, sets: [scenario.latitude], values: [30, 90]}
    """
    assert "out of range (-90, 90) deg" in refused(tmp_path, text)


def test_a_correlation_time_must_be_positive(tmp_path):
    text = """\
    study: tau
    parameters:
      tau: {unit: h, sets: [gyro_markov_rate_x.correlation_time], values: [1, 0]}
    """
    assert "correlation time must be positive" in refused(tmp_path, text)


def test_a_listed_case_must_give_every_parameter(tmp_path):
    text = """\
    study: listed
    parameters:
      doppler_noise: {unit: m/s, sets: [doppler_noise_sigma_north]}
      latitude: {unit: deg, sets: [scenario.latitude]}
    cases:
      - {doppler_noise: 0.6}
    """
    message = refused(tmp_path, text)
    assert "study.yaml:6" in message and "no value for parameter 'latitude'" in message


def test_monte_carlo_only_for_the_full_filter_and_with_profile_keys(tmp_path):
    base = GRID + """\
monte_carlo:
  profile: profile_000
  runs: 2
  cases: [{gyro_drift: 0.1, doppler_noise: 0.2, filter: suboptimal_2}]
"""
    assert "needs the flight-profile keys" in refused(tmp_path, base)
    with_keys = base.replace("sets: [gyro_markov_sigma_x, initial_sigma.gyro_constant_drift_x]",
                             "sets: [gyro_markov_sigma_x, initial_sigma.gyro_constant_drift_x]\n    profile: [imu.gyro_markov_drift_dph]")
    with_keys = with_keys.replace("sets: [doppler_noise_sigma_north, doppler_noise_sigma_east]",
                                  "sets: [doppler_noise_sigma_north, doppler_noise_sigma_east]\n    profile: [doppler.white_noise_mps]")
    assert "full-model filter" in refused(tmp_path, with_keys)
    assert load_study(write(tmp_path, with_keys.replace(", filter: suboptimal_2", ""))).monte_carlo.cases == ((0.1, 0.2),)
    wrong_unit = with_keys.replace("doppler.white_noise_mps", "doppler.white_noise_dph")
    assert "does not measure speed" in refused(tmp_path, wrong_unit)


def test_a_model_without_the_papers_states_is_refused(tmp_path):
    message = refused(tmp_path, GRID + "model: gps_pseudorange11\n")
    assert "no initial sigma" in message or "no state" in message


def test_study_values_are_read_not_evaluated(tmp_path):
    message = refused(tmp_path, GRID.replace("values: [0.01, 0.1]", "values: [0.01, '__import__(\"os\")']"))
    assert "not a number" in message


def test_a_huge_grid_is_refused_from_the_value_counts_before_it_is_built(tmp_path):
    """Issue 28: three parameters of 10,000 values (10**12 points) are refused at once, not built in memory."""
    import time
    import tracemalloc

    text = """\
    study: huge
    parameters:
      a: {unit: deg/h, sets: [gyro_markov_sigma_x], range: {from: 0.01, to: 1, count: 10000}}
      b: {unit: deg/h, sets: [gyro_markov_sigma_y], range: {from: 0.01, to: 1, count: 10000}}
      c: {unit: deg/h, sets: [gyro_markov_sigma_z], range: {from: 0.01, to: 1, count: 10000}}
    filters: [optimal]
    """
    tracemalloc.start()
    started = time.perf_counter()
    try:
        message = refused(tmp_path, text)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert time.perf_counter() - started < 20
    assert f"a study may have at most {MAX_CASES}" in message and "study.yaml:" in message, message
    assert "'b'" in message, message  # refused as soon as the counts pass the limit, before c's values are checked
    assert peak < 200 * 1024**2, f"peak {peak / 1024**2:.0f} MiB"


@pytest.mark.parametrize("name", ["../x", "a/b", "with space", "", "1st"])
def test_a_parameter_name_that_is_not_a_plain_name_is_refused_up_front(tmp_path, name):
    text = GRID.replace("  gyro_drift:", f"  {name!r}:").replace("x: gyro_drift", "")
    message = refused(tmp_path, text)
    assert "study.yaml:" in message and "parameter name" in message, message


def test_too_many_listed_values_or_cases_are_refused(tmp_path):
    values = ", ".join(["0.1"] * 10_001)
    message = refused(tmp_path, GRID.replace("values: [0.01, 0.1]", f"values: [{values}]"))
    assert "study.yaml:5" in message and "at most 10000" in message, message


def test_monte_carlo_hours_and_imu_rate_are_bounded_with_file_and_line(tmp_path):
    """Issue 28: a Monte Carlo of unbounded hours or IMU rate ran for hours or out of memory."""
    keyed = GRID.replace("sets: [gyro_markov_sigma_x, initial_sigma.gyro_constant_drift_x]",
                         "sets: [gyro_markov_sigma_x, initial_sigma.gyro_constant_drift_x]\n    profile: [imu.gyro_markov_drift_dph]")
    keyed = keyed.replace("sets: [doppler_noise_sigma_north, doppler_noise_sigma_east]",
                          "sets: [doppler_noise_sigma_north, doppler_noise_sigma_east]\n    profile: [doppler.white_noise_mps]")
    mc = keyed + "monte_carlo:\n  profile: profile_000\n  runs: 2\n  cases: [{gyro_drift: 0.1, doppler_noise: 0.2}]\n"
    assert load_study(write(tmp_path, mc + "  hours: 240\n")).monte_carlo.hours == 240
    message = refused(tmp_path, mc + "  hours: 1.0e+6\n")
    assert message.startswith(f"{tmp_path / 'study.yaml'}:") and "monte_carlo.hours: a flight of 1e+06 h is longer" in message
    message = refused(tmp_path, mc + "  imu_rate_hz: 1.0e+6\n")
    assert "monte_carlo.imu_rate_hz: an IMU rate of 1e+06 Hz is faster than modelgen flies" in message
    assert "IMU samples" in refused(tmp_path, mc + "  hours: 200\n  imu_rate_hz: 5000\n")


def test_number_text_is_read_as_in_profiles_and_lax_forms_are_refused(tmp_path):
    """YAML 1.1 reads 1e9 and 1e-2 (no dot) as text: a study read "'1e9' is not a number" where a profile reads it."""
    study = load_study(write(tmp_path, GRID.replace("values: [0.01, 0.1]", "values: [1e-2, '0.1']")))
    assert study.parameters[0].values == pytest.approx((0.01, 0.1))
    for lax in ("'1_0'", "' 1.5'", "true", "'0x10'"):
        message = refused(tmp_path, GRID.replace("values: [0.01, 0.1]", f"values: [0.01, {lax}]"))
        assert "study.yaml:5" in message and "is not a number" in message, (lax, message)


def test_a_folder_named_like_a_built_in_study_does_not_shadow_it(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "paper_gyro_doppler_1000").mkdir()
    assert load_study("paper_gyro_doppler_1000").parameters
