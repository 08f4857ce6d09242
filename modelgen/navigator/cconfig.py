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
from types import SimpleNamespace

import numpy as np
from scipy.stats import chi2

from modelgen.navigator.cconfig_fields import Field
from modelgen.navigator.sensors import SENSORS, sensor_fields, sensor_values

C_TYPES = {"double": ctypes.c_double, "int": ctypes.c_int32}


CORE_FIELDS: tuple[Field, ...] = (
    Field("lever_arm", "double", 3, "IMU to antenna in body axes [m]"),
    Field("velocity_latency", "double", 1, "GNSS velocity latency [s]"),
    Field("gate_1", "double", 1, "NIS gate of a 1-row update (odometer, barometer)"),
    Field("gate_2", "double", 1, "NIS gate of a 2-row update (NHC)"),
    Field("gate_3", "double", 1, "NIS gate of a 3-row update (ZUPT)"),
    Field("gate_gnss", "double", 1, "NIS gate of the GNSS update (chi-square of its row count)"),
    Field("deweight", "int", 1, "1: de-weight an update above the gate (R x NIS / gate), 0: reject it"),
    Field("gate_release_epochs", "int", 1, "consecutive rejected GNSS epochs before one is accepted anyway"),
    Field("zupt_gyro_max", "double", 1, "ZUPT detector: every bias-corrected rate in the window below [rad/s]"),
    Field("zupt_accel_std_max", "double", 1, "ZUPT detector: standard deviation of |f| below [m/s^2]"),
    Field("zupt_window", "int", 1, "ZUPT detector window [samples]"),
    Field("predict_samples", "int", 1, "IMU samples per covariance step"),
    Field("gyro_white", "double", 1, "gyro white noise N_g [rad/sqrt(s)]"),
    Field("accel_white", "double", 1, "accelerometer white noise N_a [m/s/sqrt(s)]"),
    Field("gyro_bias_driving", "double", 1, "gyro bias driving noise N_bg [rad/s/sqrt(s)]"),
    Field("accel_bias_driving", "double", 1, "accelerometer bias driving noise N_ba [m/s^2/sqrt(s)]"),
    Field("minimum_sigma_position", "double", 1, "floor on the receiver's position sigmas [m]"),
    Field("minimum_sigma_velocity", "double", 1, "floor on the receiver's velocity sigmas [m/s]"),
    Field("position_variance_factor", "double", 1, "factor on the GNSS position rows' variance (after the floor)"),
    Field("velocity_variance_factor", "double", 1, "factor on the GNSS velocity rows' variance (after the floor)"),
    Field("quality_factor", "double", 8, "sigma factor of GNSS quality Q = 0..7 (0: epoch not used)"),
    Field("rest_speed", "double", 1, "alignment: a GNSS epoch slower than this is at rest [m/s]"),
    Field("rest_window", "double", 1, "alignment: rest window [s]"),
    Field("heading_speed", "double", 1, "alignment: heading from the GNSS course at the first epoch this fast [m/s]"),
    Field("still_window", "int", 1, "alignment's still detector window [samples]"),
    Field("still_gyro_std_max", "double", 1, "still detector: RMS rate deviation from the window mean below [rad/s]"),
    Field("still_accel_std_max", "double", 1, "still detector: RMS force deviation below [m/s^2]"),
    Field("rest_span_min", "double", 1, "alignment: shortest rest window [s]"),
    Field("roll_pitch_sigma", "double", 1, "initial roll and pitch sigma [rad]"),
    Field("heading_extra_sigma", "double", 1, "added root-sum-square to atan(sigma_v / speed) [rad]"),
    Field("velocity_sigma", "double", 1, "initial velocity sigma [m/s]"),
    Field("position_sigma", "double", 1, "initial horizontal position sigma [m]"),
    Field("height_sigma", "double", 1, "initial height sigma [m]"),
    Field("gyro_bias_sigma", "double", 1, "initial gyro bias sigma [rad/s]"),
    Field("accel_bias_sigma", "double", 1, "initial accelerometer bias sigma [m/s^2]"),
    Field("gyro_scale_factor_sigma", "double", 1, "initial gyro scale-factor sigma [1] (models with that block)"),
    Field("accel_scale_factor_sigma", "double", 1, "initial accelerometer scale-factor sigma [1]"),
    Field("parameters", "double", "P", "the model's free parameters (configuration parameters: or defaults), "
                                       "in the order of NavigatorSpec.free_parameters"),
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
