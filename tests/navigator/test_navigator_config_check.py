"""The C navigator's configuration check (<model>_navigator_config_check): generated from the field list and the schema.

Table-driven from modelgen/data/replay_config.schema.json: for every field of cconfig.FIELDS that comes from a key,
every bound of that key's schema node (and non-finite numbers) yields a value the Python loader refuses; the same
value, as the C struct holds it, is refused by the compiled C with the field's own NAV_ERR_CONFIG_* status.  A new
field or a new bound in the schema is covered without touching this file.
"""

from __future__ import annotations

import ctypes
import math
import re
from pathlib import Path

import pytest
import yaml

from modelgen.errors import ModelError
from modelgen.navigator import cconfig
from modelgen.navigator.config import load_config

DATA = Path(__file__).parent / "data"
EXCERPT = DATA / "excerpt.yaml"
#: sample counts of the good struct (100 Hz: a 0.5 s ZUPT and still window, a 0.1 s covariance step)
SAMPLES = {"zupt_window": 50, "predict_samples": 10, "still_window": 50}


def _violations(item: cconfig.Field) -> list:
    """Values of the field's key its schema node refuses: just past each bound, and the non-finite numbers."""
    node = cconfig._value_node(cconfig.schema_node(item.key))
    if node.get("type") == "boolean":
        return [2, -1]
    if "enum" in node:
        return ["neither"]
    out = []
    for name in ("minimum", "exclusiveMinimum"):
        if name in node:
            out += ([node[name]] if name == "exclusiveMinimum" else []) + [node[name] - 1]
    for name in ("maximum", "exclusiveMaximum"):
        if name in node:
            out += ([node[name]] if name == "exclusiveMaximum" else []) + [node[name] + 1]
    if node.get("type") == "integer":
        return out
    return out + [math.nan, math.inf, -math.inf]


def _cases() -> list:
    return [pytest.param(item, value, id=f"{item.name}={value}") for item in cconfig.FIELDS if item.key
            for value in _violations(item)]


def _c_value(item: cconfig.Field, value, good):
    """The struct's value for a key value (the field's scale; a switch or choice outside 0/1 as 2)."""
    node = cconfig._value_node(cconfig.schema_node(item.key))
    if node.get("type") == "boolean" or "enum" in node:
        return 2 if isinstance(value, str) else value
    if item.scale == "chi2":
        from scipy.stats import chi2

        return float(chi2.ppf(value, 1)) if 0 <= value <= 1 else math.nan
    if item.scale == "positive":  # the good value's own positive factors (unit x factor)
        return value * good / _key_value(item)
    return int(value) if item.ctype == "int" else value * float(item.scale)


def _key_value(item: cconfig.Field) -> float:
    node = yaml.safe_load(EXCERPT.read_text())
    for part in item.key.split("."):
        node = node[part]
    return node


def _with_key(tmp_path: Path, key: str, value) -> Path:
    """The excerpt's configuration with one key set to ``value`` (a list's first entry, a mapping's entry)."""
    data = yaml.safe_load(EXCERPT.read_text())
    for section in ("imu", "gnss"):
        data[section]["file"] = str(DATA / data[section]["file"])
    *parents, last = key.split(".")
    node = data
    for part in parents:
        node = node.setdefault(part, {})
    old = node.get(last)
    node[last] = ([value] + list(old[1:]) if isinstance(old, list) else {**old, 1: value} if isinstance(old, dict)
                  else {"some_parameter": value} if key == "parameters" else [value, 0.0, 0.0]
                  if key.endswith("lever_arm_m") else value)
    path = tmp_path / "nav.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


_NAVIGATOR: dict = {}


def _navigator():
    """The excerpt model's compiled C navigator (the compile cache's), its spec and a good struct's field values."""
    if not _NAVIGATOR:
        from modelgen.navigator.cnav import cached_c_navigator
        from tests.navigator.test_navigator import _excerpt_spec

        spec = _excerpt_spec()
        navigator, _ = cached_c_navigator(spec)
        good = cconfig.values(load_config(EXCERPT), spec, SAMPLES["zupt_window"], SAMPLES["predict_samples"],
                              SAMPLES["still_window"])
        _NAVIGATOR.update(navigator=navigator, spec=spec, good=good)
    return _NAVIGATOR["navigator"], _NAVIGATOR["spec"], _NAVIGATOR["good"]


def _c_status(field_values: dict) -> int:
    navigator, spec, _ = _navigator()
    state = ctypes.create_string_buffer(navigator.size)
    struct = cconfig.to_structure(field_values, len(spec.free_parameters))
    return int(navigator.configure(state, ctypes.byref(struct)))


def _with_field(good: dict, item: cconfig.Field, value) -> dict:
    values = dict(good)
    values[item.name] = [value] + list(good[item.name][1:]) if isinstance(good[item.name], list) else value
    return values


def test_every_field_is_bounded_and_every_keyed_field_has_a_refused_value():
    """No field of the struct goes unchecked: each has a key with bounds or finiteness, or bounds of its own."""
    for item in cconfig.FIELDS:
        b = cconfig.bounds(item)
        assert b.low is not None or b.high is not None or b.finite, item.name
        if item.key:
            assert _violations(item), item.name
    assert len(set(cconfig.CONFIG_STATUS)) == len(cconfig.FIELDS)
    from modelgen.navigator.cnav import NAV_STATUS

    assert min(cconfig.CONFIG_STATUS) > max(code for code, _ in NAV_STATUS.values())  # no status means two things


@pytest.mark.compile
def test_the_good_configuration_passes_both_checks():
    _, _, good = _navigator()
    assert _c_status(good) == 0
    assert cconfig.check(good, {"WINDOW_MAX": cconfig.WINDOW_MAX}) is None


@pytest.mark.compile
@pytest.mark.parametrize("item, value", _cases())
def test_a_value_the_loader_refuses_is_refused_by_the_c_with_its_field_status(tmp_path, item, value):
    with pytest.raises(ModelError, match=re.escape("nav.yaml:")):
        load_config(_with_key(tmp_path, item.key, value))
    _, _, good = _navigator()
    c_value = _c_value(item, value, good[item.name] if not isinstance(good[item.name], list)
                       else good[item.name][0])
    if item.absent is not None and c_value == item.absent:
        assert _c_status(_with_field(good, item, c_value)) == 0  # the struct's "not given"
        return
    values = _with_field(good, item, c_value)
    assert _c_status(values) == cconfig.status_of(item)
    assert cconfig.check(values, {"WINDOW_MAX": cconfig.WINDOW_MAX}) is item  # the Python navigator's twin


@pytest.mark.compile
@pytest.mark.parametrize("name, value", [("zupt_window", 1), ("zupt_window", cconfig.WINDOW_MAX + 1),
                                         ("still_window", 1), ("predict_samples", 0),
                                         ("rest_span_min", "rest_window + 1")])
def test_derived_sizes_and_the_rest_span_are_checked(name, value):
    """Sample counts below the detectors' least or above the C's buffers, and a rest span longer than the window."""
    from modelgen.navigator.cnav import REST_MAX

    _, _, good = _navigator()
    item = next(f for f in cconfig.FIELDS if f.name == name)
    value = good["rest_window"] + 1 if value == "rest_window + 1" else value
    values = _with_field(good, item, value)
    assert _c_status(values) == cconfig.status_of(item)
    assert cconfig.check(values, {"WINDOW_MAX": cconfig.WINDOW_MAX, "REST_MAX": REST_MAX}) is item
    if name == "still_window":
        assert _c_status(_with_field(good, item, REST_MAX + 1)) == cconfig.status_of(item)


@pytest.mark.compile
def test_the_header_names_every_status_and_the_check(tmp_path):
    from modelgen.navigator.cnav import generate_c_navigator
    from tests.navigator.test_navigator import _excerpt_spec

    spec = _excerpt_spec()
    header = (generate_c_navigator(spec, tmp_path / "nav") / f"{spec.name}_navigator.h").read_text()
    assert f"int {spec.name}_navigator_config_check(" in header
    for item in cconfig.FIELDS:
        assert f"#define {spec.name.upper()}_{cconfig.status_name(item)} {cconfig.status_of(item)} " in header


@pytest.mark.compile
def test_a_zupt_window_beyond_the_default_buffer_flies_in_c_and_python_alike(tmp_path):
    """A ZUPT window of 3 s at 100 Hz (300 samples, beyond the default 256-sample detector buffer) passes the loader,
    and both navigators fly it: the C is built with the detector buffer the configuration needs (512), not refused
    by a fixed one, and agrees with the Python navigator."""
    from modelgen.navigator.config import load_config
    from modelgen.navigator.cnav import WINDOW_MAX, window_capacity
    from modelgen.navigator.replay import run_replay
    from tests.navigator.test_navigator import _excerpt_inputs

    path = _with_key(tmp_path, "zupt.window_s", 3.0)
    assert window_capacity(load_config(path), _excerpt_inputs()[1].time) == 512 > WINDOW_MAX
    result = run_replay(path, None, echo=lambda _: None, navigator="both")
    assert result.summary["navigator"] == "c"
    assert result.summary["c_python_max_difference_m"] <= 1e-3


@pytest.mark.compile
def test_a_c_navigator_built_with_a_smaller_detector_buffer_refuses_the_configuration_before_flying(tmp_path):
    """The same 300-sample window given to a C navigator built with the default buffer: one error naming the
    buffer the configuration needs and the one it was built with, before anything is flown."""
    from modelgen.navigator.config import load_config
    from modelgen.navigator.cnav import WINDOW_MAX, cached_c_navigator, fly_c
    from tests.navigator.test_navigator import _excerpt_inputs, _excerpt_spec

    config = load_config(_with_key(tmp_path, "zupt.window_s", 3.0))
    navigator, _ = cached_c_navigator(_excerpt_spec())
    assert navigator.window_max == WINDOW_MAX
    with pytest.raises(ModelError, match=r"zero-velocity window needs a detector buffer of 512 IMU samples; the C "
                                         r"navigator was built with 256"):
        fly_c(config, _excerpt_inputs()[1], navigator)

@pytest.mark.compile
@pytest.mark.parametrize("key", ["zupt.window_s", "alignment.still_window_s"])
@pytest.mark.parametrize("window_s", [70.0, 1.0e4, 1.0e9])
def test_a_window_longer_than_the_log_is_refused_alike_as_one_error_line(tmp_path, window_s, key):
    """A detector window longer than the whole log (70 s: the 61-s excerpt, within a power-of-two buffer; 1e4 s: more
    samples than the log; 1e9 s: past a 32-bit count, which would wrap in the struct) gets no buffer of its size: each navigator refuses it as one 'modelgen: error:'
    line naming FILE:LINE and the key, as longer than the log, before any navigator is built (the still window was
    the alignment's diagnosis with no configuration line, a ZUPT window flew with no ZUPT and said nothing), exit
    2, no traceback; before, a huge window made a ring the C compiler refused, or a count that wrapped.  The fields'
    own bounds (a count past the buffer) are test_derived_sizes_and_the_rest_span_are_checked's."""
    from tests.cli_in_process import run_modelgen

    path = _with_key(tmp_path, key, window_s)
    line = next(i for i, text in enumerate(path.read_text().splitlines(), start=1) if "window_s: " + str(window_s) in text)
    for navigator in ("c", "python"):
        result = run_modelgen(["replay", path, "--out", tmp_path / navigator, "--no-figures", "--navigator", navigator],
                              tmp_path, timeout=600)
        assert result.returncode == 2, result.stderr
        errors = [x for x in result.stderr.splitlines() if x.startswith("modelgen: error:")]
        assert len(errors) == 1 and errors[0].startswith(f"modelgen: error: {path}:{line}: {key}: "), result.stderr
        assert "more than the whole IMU log has" in errors[0], errors[0]  # before any navigator is built
        assert "Traceback" not in result.stderr
