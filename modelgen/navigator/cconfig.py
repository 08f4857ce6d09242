"""The C navigator's configuration: ONE field list, from which the C struct, its ctypes twin and the packed bytes come.

:data:`FIELDS` names every configuration value the C navigator reads (name, C
type, count, meaning and unit).  From it come the ``<model>_navigator_config``
struct in the generated header (:func:`c_struct`), the ctypes Structure the
host passes to ``<model>_navigator_configure`` (:func:`structure`), the bytes
the qemu driver reads (:func:`pack`), and the values the Python navigator reads
(:func:`values`, the same numbers under the same names).  The count ``"P"`` is
the model's number of free parameters (:attr:`NavigatorSpec.free_parameters`,
at least one entry so that C99 has no empty array).
"""

from __future__ import annotations

import ctypes
import math
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
from scipy.stats import chi2

from modelgen.errors import ModelError
from modelgen.navigator.cconfig_fields import WINDOW_SAMPLES_MIN, Field
from modelgen.navigator.config import DEG, MICRO_G
from modelgen.navigator.config_schema import load_schema
from modelgen.navigator.sensors import SENSORS, sensor_fields, sensor_values

C_TYPES = {"double": ctypes.c_double, "int": ctypes.c_int32}


CORE_FIELDS: tuple[Field, ...] = (
    Field("lever_arm", "double", 3, "IMU to antenna in body axes [m]", key="gnss.lever_arm_m"),
    Field("velocity_latency", "double", 1, "GNSS velocity latency [s]", key="gnss.velocity_latency_s"),
    Field("gate_1", "double", 1, "NIS gate of a 1-row update (odometer, barometer)",
          key="filter.nis_gate_probability", scale="chi2"),
    Field("gate_2", "double", 1, "NIS gate of a 2-row update (NHC)", key="filter.nis_gate_probability", scale="chi2"),
    Field("gate_3", "double", 1, "NIS gate of a 3-row update (ZUPT)", key="filter.nis_gate_probability", scale="chi2"),
    Field("gate_gnss", "double", 1, "NIS gate of the GNSS update (chi-square of its row count)",
          key="filter.nis_gate_probability", scale="chi2"),
    Field("deweight", "int", 1, "1: de-weight an update above the gate (R x NIS / gate), 0: reject it",
          key="filter.gate_action"),
    Field("gate_release_epochs", "int", 1, "consecutive rejected GNSS epochs before one is accepted anyway",
          key="filter.gate_release_epochs"),
    Field("zupt_gyro_max", "double", 1, "ZUPT detector: every bias-corrected rate in the window below [rad/s]",
          key="zupt.gyro_max_deg_s", scale=DEG),
    Field("zupt_accel_std_max", "double", 1, "ZUPT detector: standard deviation of |f| below [m/s^2]",
          key="zupt.accel_std_max_m_s2"),
    Field("zupt_window", "int", 1, "ZUPT detector window [samples]",
          minimum=WINDOW_SAMPLES_MIN, maximum="WINDOW_MAX", origin="zupt.window_s"),
    Field("predict_samples", "int", 1, "IMU samples per covariance step", minimum=1, origin="filter.predict_period_s"),
    Field("gyro_white", "double", 1, "gyro white noise N_g [rad/sqrt(s)]",
          key="noise.gyro_white.value", scale="positive"),
    Field("accel_white", "double", 1, "accelerometer white noise N_a [m/s/sqrt(s)]",
          key="noise.accel_white.value", scale="positive"),
    Field("gyro_bias_driving", "double", 1, "gyro bias driving noise N_bg [rad/s/sqrt(s)]",
          key="noise.gyro_bias_driving.value", scale="positive"),
    Field("accel_bias_driving", "double", 1, "accelerometer bias driving noise N_ba [m/s^2/sqrt(s)]",
          key="noise.accel_bias_driving.value", scale="positive"),
    Field("minimum_sigma_position", "double", 1, "floor on the receiver's position sigmas [m]",
          key="gnss.minimum_sigma_position_m"),
    Field("minimum_sigma_velocity", "double", 1, "floor on the receiver's velocity sigmas [m/s]",
          key="gnss.minimum_sigma_velocity_m_s"),
    Field("position_variance_factor", "double", 1, "factor on the GNSS position rows' variance (after the floor)",
          key="gnss.position_variance_factor"),
    Field("velocity_variance_factor", "double", 1, "factor on the GNSS velocity rows' variance (after the floor)",
          key="gnss.velocity_variance_factor"),
    Field("quality_factor", "double", 8, "sigma factor of GNSS quality Q = 0..7 (0: epoch not used)",
          key="gnss.quality_factor", absent=0.0),
    Field("rest_speed", "double", 1, "alignment: a GNSS epoch slower than this is at rest [m/s]",
          key="alignment.rest_speed_m_s"),
    Field("rest_window", "double", 1, "alignment: rest window [s]", key="alignment.rest_window_s"),
    Field("heading_speed", "double", 1, "alignment: heading from the GNSS course at the first epoch this fast [m/s]",
          key="alignment.heading_speed_m_s"),
    Field("still_window", "int", 1, "alignment's still detector window [samples]",
          minimum=WINDOW_SAMPLES_MIN, maximum="REST_MAX", origin="alignment.still_window_s"),
    Field("still_gyro_std_max", "double", 1, "still detector: RMS rate deviation from the window mean below [rad/s]",
          key="alignment.gyro_std_max_deg_s", scale=DEG),
    Field("still_accel_std_max", "double", 1, "still detector: RMS force deviation below [m/s^2]",
          key="alignment.accel_std_max_m_s2"),
    Field("rest_span_min", "double", 1, "alignment: shortest rest window [s]",
          key="alignment.rest_min_s", not_above="rest_window"),
    Field("roll_pitch_sigma", "double", 1, "initial roll and pitch sigma [rad]",
          key="initial.roll_pitch_sigma_deg", scale=DEG),
    Field("heading_extra_sigma", "double", 1, "added root-sum-square to atan(sigma_v / speed) [rad]",
          key="initial.heading_extra_sigma_deg", scale=DEG),
    Field("velocity_sigma", "double", 1, "initial velocity sigma [m/s]", key="initial.velocity_sigma_m_s"),
    Field("position_sigma", "double", 1, "initial horizontal position sigma [m]", key="initial.position_sigma_m"),
    Field("height_sigma", "double", 1, "initial height sigma [m]", key="initial.height_sigma_m"),
    Field("gyro_bias_sigma", "double", 1, "initial gyro bias sigma [rad/s]",
          key="initial.gyro_bias_sigma_deg_s", scale=DEG),
    Field("accel_bias_sigma", "double", 1, "initial accelerometer bias sigma [m/s^2]",
          key="initial.accel_bias_sigma_ug", scale=MICRO_G),
    Field("gyro_scale_factor_sigma", "double", 1, "initial gyro scale-factor sigma [1] (models with that block)",
          key="initial.gyro_scale_factor_sigma_ppm", scale=1e-6, absent=0.0),
    Field("accel_scale_factor_sigma", "double", 1, "initial accelerometer scale-factor sigma [1]",
          key="initial.accel_scale_factor_sigma_ppm", scale=1e-6, absent=0.0),
    Field("parameters", "double", "P", "the model's free parameters (configuration parameters: or defaults), "
                                       "in the order of NavigatorSpec.free_parameters", key="parameters"),
)
#: the one field list: the navigator's own fields, then every aiding sensor's (modelgen.navigator.sensors.SENSORS)
FIELDS: tuple[Field, ...] = CORE_FIELDS + sensor_fields(SENSORS)


def count_of(item: Field, n_parameters: int) -> int:
    """A field's element count for a model with ``n_parameters`` free parameters."""
    return max(1, n_parameters) if item.count == "P" else int(item.count)


def c_struct(model: str, n_parameters: int) -> str:
    """The C typedef ``<model>_navigator_config`` (one member per field, commented with its meaning)."""
    lines = ["typedef struct {"]
    for item in FIELDS:
        n = count_of(item, n_parameters)
        suffix = f"[{n}]" if item.count != 1 else ""
        lines.append(f"    {item.ctype} {item.name}{suffix};  /* {item.meaning} */")
    lines.append(f"}} {model}_navigator_config;")
    return "\n".join(lines)


def structure(n_parameters: int) -> type[ctypes.Structure]:
    """The ctypes twin of the C struct for a model with ``n_parameters`` free parameters."""
    members = []
    for item in FIELDS:
        kind = C_TYPES[item.ctype]
        members.append((item.name, kind * count_of(item, n_parameters) if item.count != 1 else kind))
    return type(f"NavigatorConfig{n_parameters}", (ctypes.Structure,), {"_fields_": members})


def values(config, spec, zupt_window: int, predict_samples: int, still_window: int, table=SENSORS) -> dict:
    """Every field's value for a configuration, a model spec and the log's sample counts (SI).

    ``table``: the aiding sensors whose fields are filled (the C struct's are :data:`SENSORS`').
    """
    gates = {m: float(chi2.ppf(config.nis_gate_probability, m)) for m in (1, 2, 3, len(spec.gnss_rows))}
    quality = [0.0] * 8
    for q, factor in config.quality_factor.items():
        if 0 <= q <= 7:
            quality[q] = factor
    out = {
        "lever_arm": list(config.lever_arm), "velocity_latency": config.velocity_latency,
        "gate_1": gates[1], "gate_2": gates[2], "gate_3": gates[3], "gate_gnss": gates[len(spec.gnss_rows)],
        "deweight": int(config.gate_action == "deweight"), "gate_release_epochs": config.gate_release_epochs,
        "zupt_gyro_max": config.zupt_gyro_max,
        "zupt_accel_std_max": config.zupt_accel_std_max, "zupt_window": zupt_window,
        "predict_samples": predict_samples,
        "gyro_white": config.noise["gyro_white"].si, "accel_white": config.noise["accel_white"].si,
        "gyro_bias_driving": config.noise["gyro_bias_driving"].si,
        "accel_bias_driving": config.noise["accel_bias_driving"].si,
        "minimum_sigma_position": config.minimum_sigma_position,
        "minimum_sigma_velocity": config.minimum_sigma_velocity, "quality_factor": quality,
        "position_variance_factor": config.gnss_position_variance_factor,
        "velocity_variance_factor": config.gnss_velocity_variance_factor,
        "rest_speed": config.rest_speed, "rest_window": config.rest_window, "heading_speed": config.heading_speed,
        "still_window": still_window, "still_gyro_std_max": config.still_gyro_std_max,
        "still_accel_std_max": config.still_accel_std_max, "rest_span_min": config.rest_span_min,
        "roll_pitch_sigma": config.roll_pitch_sigma, "heading_extra_sigma": config.heading_extra_sigma,
        "velocity_sigma": config.velocity_sigma, "position_sigma": config.position_sigma,
        "height_sigma": config.height_sigma, "gyro_bias_sigma": config.gyro_bias_sigma,
        "accel_bias_sigma": config.accel_bias_sigma,
        "gyro_scale_factor_sigma": config.gyro_scale_factor_sigma or 0.0,
        "accel_scale_factor_sigma": config.accel_scale_factor_sigma or 0.0,
        "parameters": spec.free_values(config) or [0.0],
    }
    out.update(sensor_values(config, table))
    assert set(out) == {f.name for f in CORE_FIELDS + sensor_fields(table)}, "cconfig.values must fill every field"
    return out


def namespace(field_values: dict) -> SimpleNamespace:
    """The values as attributes (the Python navigator reads ``cfg.lever_arm`` as the C reads ``cfg->lever_arm``)."""
    return SimpleNamespace(**{k: (np.array(v, float) if isinstance(v, list) else v) for k, v in field_values.items()})


def to_structure(field_values: dict, n_parameters: int) -> ctypes.Structure:
    """The ctypes struct filled with the values."""
    struct = structure(n_parameters)()
    for item in FIELDS:
        value = field_values[item.name]
        if item.count == 1:
            setattr(struct, item.name, value)
        else:
            array = getattr(struct, item.name)
            for i, v in enumerate(value):
                array[i] = v
    return struct


def pack(field_values: dict, n_parameters: int) -> bytes:
    """The struct's bytes (host layout; doubles and 32-bit ints only, so the ARM EABI layout is the same)."""
    return bytes(to_structure(field_values, n_parameters))


# --- where each field's value may lie: from the field list and the replay configuration's schema -------------------

#: the C navigator's default capacities a field may be bounded by (header ``<P>_NAV_<name>``), each set per build
#: from the configuration and the log: WINDOW_MAX the zero-velocity detector's window (modelgen.navigator.cnav.
#: window_capacity), REST_MAX the alignment ring (cnav.rest_capacity)
WINDOW_MAX = 256
#: the range of the struct's 32-bit ints: a larger count (a window of days) is refused before it is packed, where
#: it would wrap to a value the C's own check could not tell from a good one
C_INT_MIN, C_INT_MAX = -2**31, 2**31 - 1


#: the alignment ring's default capacity (IMU samples; ``<P>_NAV_REST_MAX``)
REST_MAX = 1024


def rest_capacity(rest_window_s: float, still_window_s: float, zupt_window_s: float, time) -> int:
    """The alignment ring a log needs: every rest window and the detectors' windows fit.

    The most samples in any ``rest_window_s`` span of the log plus two (the epoch's own sample), at least the
    still detector's and the ZUPT's windows plus one, but never more than the log's own samples need (a window
    longer than the log is refused by its field's bound, not given a ring of its size); rounded up to a power of
    two, at least :data:`REST_MAX`.
    """
    import numpy as np

    time = np.asarray(time, float)
    need = int(np.max(np.arange(len(time)) - np.searchsorted(time, time - rest_window_s, side="left"))) + 3
    median_dt = float(np.median(np.diff(time)))

    def samples(window_s: float) -> int:
        return min(max(WINDOW_SAMPLES_MIN, int(round(window_s / median_dt))), len(time)) + 1

    need = max(need, samples(still_window_s), samples(zupt_window_s))
    return max(REST_MAX, 1 << (need - 1).bit_length())


def window_capacity(zupt_window_s: float, time) -> int:
    """The zero-velocity detector's window buffer a log needs: the ZUPT window's samples at the log's median IMU
    rate (as the configuration's field is computed) plus one, rounded up to a power of two, at least
    :data:`WINDOW_MAX`; never more than the log's own samples need (a window longer than the log is refused by the
    field's bound, not given a buffer of its size).  A 1 kHz IMU with a 0.5-s window needs 512."""
    import numpy as np

    time = np.asarray(time, float)
    median_dt = float(np.median(np.diff(time)))
    need = min(max(WINDOW_SAMPLES_MIN, int(round(zupt_window_s / median_dt))), len(time)) + 1
    return max(WINDOW_MAX, 1 << (need - 1).bit_length())


#: the status of the first refused field is CONFIG_STATUS_BASE + its index in FIELDS (``<P>_NAV_ERR_CONFIG_<NAME>``)
CONFIG_STATUS_BASE = 32


@dataclass(frozen=True)
class Bounds:
    """Where one field's values (every element) may lie: low and high (a number, a capacity name or None), whether
    each is excluded, whether a double must be finite, the value meaning "not given", the field it must not exceed."""

    low: float | int | str | None = None
    low_open: bool = False
    high: float | int | str | None = None
    high_open: bool = False
    finite: bool = False
    absent: float | None = None
    not_above: str = ""


def schema_node(key: str) -> dict:
    """The schema node of a dotted configuration key (ModelError-free: a key the schema lacks is a KeyError)."""
    node = load_schema()
    for part in key.split("."):
        node = node["properties"][part]
    return node


def _value_node(node: dict) -> dict:
    """The node that bounds each value: an array's items, a mapping's values, else the node itself."""
    if isinstance(node.get("items"), dict):
        return node["items"]
    if isinstance(node.get("additionalProperties"), dict):
        return node["additionalProperties"]
    return node


def _mapped(item: Field, bound: float) -> float:
    """A schema bound of the field's key as a bound of the field's value (its ``scale``)."""
    if isinstance(item.scale, (int, float)):
        return bound * float(item.scale)
    if item.scale == "positive" and bound == 0:
        return 0.0
    if item.scale == "chi2" and bound in (0, 1):
        return 0.0 if bound == 0 else math.inf
    raise ValueError(f"cconfig field {item.name}: the bound {bound!r} of {item.key} does not carry over "
                     f"through scale {item.scale!r}")


def bounds(item: Field) -> Bounds:
    """The field's bounds: its key's schema bounds mapped by its scale, or its own (derived values)."""
    low = high = None
    low_open = high_open = False
    if item.key:
        node = _value_node(schema_node(item.key))
        if node.get("type") == "boolean" or len(node.get("enum", ())) == 2:
            low, high = 0, 1  # a switch or a two-way choice: 0 or 1
        for name, is_low, is_open in (("minimum", True, False), ("exclusiveMinimum", True, True),
                                      ("maximum", False, False), ("exclusiveMaximum", False, True)):
            if name in node:
                value = _mapped(item, node[name])
                value = int(value) if item.ctype == "int" else value
                if is_low:
                    low, low_open = value, is_open
                else:
                    high, high_open = value, is_open
    else:
        low, high = item.minimum, item.maximum
    if high == math.inf and not high_open:
        high = None  # an included infinity: no upper bound, and infinity allowed
        finite = False
    else:
        finite = item.ctype == "double"
    return Bounds(low, low_open, high, high_open, finite, item.absent, item.not_above)


def status_name(item: Field) -> str:
    """The field's refusal status, without the ``<P>_`` prefix."""
    return f"NAV_ERR_CONFIG_{item.name.upper()}"


def status_of(item: Field) -> int:
    return CONFIG_STATUS_BASE + FIELDS.index(item)


#: status -> the field it refuses
CONFIG_STATUS: dict[int, Field] = {status_of(f): f for f in FIELDS}


def _c_number(value, ctype: str, P: str) -> str:
    if isinstance(value, str):
        return f"{P}_NAV_{value}"
    return str(int(value)) if ctype == "int" else repr(float(value))


def c_condition(item: Field, x: str, P: str) -> str:
    """The C expression true when the element ``x`` of the field is acceptable (false for NaN)."""
    b = bounds(item)
    parts = []
    if b.low is not None:
        parts.append(f"{x} {'>' if b.low_open else '>='} {_c_number(b.low, item.ctype, P)}")
    elif b.finite:
        parts.append(f"{x} > -HUGE_VAL")
    if b.high is not None:
        parts.append(f"{x} {'<' if b.high_open else '<='} {_c_number(b.high, item.ctype, P)}")
    elif b.finite:
        parts.append(f"{x} < HUGE_VAL")
    if b.not_above:
        parts.append(f"{x} <= c->{b.not_above}")
    condition = " && ".join(parts) or "1"
    if b.absent is not None:
        condition = f"{x} == {_c_number(b.absent, item.ctype, P)} || ({condition})"
    return condition


def c_checks(P: str, n_parameters: int) -> list[dict]:
    """What the template's ``<model>_navigator_config_check`` emits per field: the condition, element count, status."""
    out = []
    for item in FIELDS:
        n = count_of(item, n_parameters)
        x = f"c->{item.name}[i]" if item.count != 1 else f"c->{item.name}"
        out.append({"name": item.name, "status": status_name(item), "code": status_of(item),
                    "words": describe(item, {"WINDOW_MAX": WINDOW_MAX}),
                    "count": n if item.count != 1 else None, "condition": c_condition(item, x, P)})
    return out


def _accepts(item: Field, x: float, field_values: dict, capacities: dict) -> bool:
    """The Python twin of :func:`c_condition` (a capacity not in ``capacities`` does not bound)."""
    b = bounds(item)
    if b.absent is not None and x == b.absent:
        return True
    if math.isnan(x):
        return False

    def number(value):
        return capacities.get(value) if isinstance(value, str) else value

    low, high = number(b.low), number(b.high)
    if b.finite and not math.isfinite(x):
        return False
    if item.ctype == "int" and not C_INT_MIN <= x <= C_INT_MAX:  # would wrap in the struct's 32-bit int
        return False
    if low is not None and not (x > low if b.low_open else x >= low):
        return False
    if high is not None and not (x < high if b.high_open else x <= high):
        return False
    return not b.not_above or x <= field_values[b.not_above]


def check(field_values: dict, capacities: dict) -> Field | None:
    """The first field (FIELDS order, the C's) with an element out of its bounds, or None: the Python navigator's
    twin of ``<model>_navigator_config_check``.  ``capacities``: the C's capacities that bound it (name -> size)."""
    for item in FIELDS:
        if item.name not in field_values:
            continue
        value = field_values[item.name]
        for x in (value if isinstance(value, (list, tuple, np.ndarray)) else [value]):
            if not _accepts(item, float(x), field_values, capacities):
                return item
    return None


def describe(item: Field, capacities: dict) -> str:
    """The field's bounds in words ('> 0 and finite', '0 (not given) or >= 1' ...)."""
    b = bounds(item)
    words = []
    for value, sign in ((b.low, ">" if b.low_open else ">="), (b.high, "<" if b.high_open else "<=")):
        if value is not None:
            shown = f"{value:g}" if not isinstance(value, str) else (
                f"{capacities[value]} (the C navigator's {value})" if value in capacities
                else f"the C navigator's {value}")
            words.append(f"{sign} {shown}")
    if b.not_above:
        words.append(f"<= {b.not_above}")
    if b.finite:
        words.append("finite")
    text = " and ".join(words) or "any value"
    return f"{b.absent:g} (not given) or ({text})" if b.absent is not None else text


def refusal(config_path: str, item: Field, value, capacities: dict, who: str, status: int | None = None) -> ModelError:
    """The one error of a configuration the navigator (``who``: 'C' or 'Python') refuses: the key's file:line, the
    field, its value and its bounds (and the C's status)."""
    from modelgen.navigator.config import key_place

    key = item.key or item.origin or item.name
    where = key_place(config_path, key)
    code = f" (status {status_name(item)} = {status})" if status is not None else ""
    return ModelError(f"{where}: {key}: the {who} navigator refuses its configuration field {item.name} = "
                      f"{_shown(value)}{code}: it must be {describe(item, capacities)}")


def _shown(value) -> str:
    if isinstance(value, (list, tuple, np.ndarray)):
        return "[" + ", ".join(f"{float(v):g}" for v in value) + "]"
    return f"{value:g}" if isinstance(value, float) else str(value)
