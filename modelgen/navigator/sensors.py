"""The aiding sensors, one table entry each: what a sensor reads, how its rows are built, when it is used.

:data:`SENSORS` lists every aiding sensor of the navigator: GNSS position and
velocity (the model file's own measurement, with the lever arm), the
zero-velocity update, the non-holonomic constraint, the odometer (wheel speed
along body x at a lever arm) and the barometer (height).  An entry
(:class:`AidingSensor`) says

* ``section``: its configuration section (``zupt:``, ``odometer:`` ...) and
  ``enabled``: the configuration field that switches it on;
* ``stream``: what it reads: ``gnss`` (the GNSS epochs), ``imu`` (a
  constraint tried at every covariance step) or its own log (``odometer``,
  ``barometer``: a time and value CSV, :mod:`modelgen.navigator.logs.scalar_csv`),
  whose latest sample not yet taken is taken at each covariance step;
* ``form``: how its measurement rows z and H are built from the spec's blocks
  (:data:`FORMS`: ``model`` the model's own generated H, ``velocity`` the
  velocity block, ``body_velocity`` the body-axis velocity at a lever arm
  (attitude and velocity blocks), ``height`` the height of the position block);
  ``axes`` the body axes of a ``body_velocity`` form;
* ``sigmas``: the standard deviation of each row (expressions over the
  configuration struct ``cfg``); their count is the gate's degrees of freedom;
* ``condition``: when it is used, one expression valid in C and, with ``->``
  read as ``.`` and ``&&`` as ``and``, in Python (:func:`python_expression`),
  over ``speed`` (navigator speed [m/s]), ``still`` (the zero-velocity
  detector), ``rate_norm`` (|gyro - bias| [rad/s]), ``fresh`` (a new sample
  of its stream) and ``cfg``, so that the C and the Python navigator cannot
  disagree on it;
* ``group``: of the entries of one group (``motion``: ZUPT, NHC) only the first
  whose condition holds is tried at a covariance step;
* ``fields``: its configuration fields (:class:`modelgen.navigator.cconfig.Field`,
  added to the one field list the C struct comes from) and ``values``: their
  values from a configuration.

The Python navigator (:func:`modelgen.navigator.navigator.fly`) and the C
navigator's template iterate over the entries; a new sensor is one entry here
(with a form, or the model file's own measurement) and its configuration
section.  :func:`rows` builds an entry's z and H in Python; the template emits
the same arithmetic per entry in C.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from modelgen.navigator.cconfig_fields import Field
from modelgen.navigator.config import DEG

#: measurement forms: what each builds from the spec's blocks
FORMS = {
    "model": "the model file's own measurement rows and generated H (GNSS position and velocity at the lever arm)",
    "velocity": "the velocity block: z = the navigator's velocity (the truth is zero)",
    "body_velocity": "z = (C_n^b v_n + omega_b x l)[axes] - measured; H = [-C_n^b [v x], C_n^b][axes] on the "
                     "attitude and velocity blocks",
    "height": "z = h - measured; H picks the height state of the position block",
}
#: streams other than the GNSS epochs and the IMU: a log of time and one value (modelgen.navigator.logs.scalar_csv)
LOG_STREAMS = ("odometer", "barometer")


@dataclass(frozen=True)
class AidingSensor:
    """One aiding sensor (see the module docstring for each field)."""

    name: str
    section: str
    stream: str  # "gnss", "imu" or a LOG_STREAMS log
    form: str  # one of FORMS
    sigmas: tuple[str, ...]  # per row: a cfg expression [the row's unit]
    condition: str
    enabled: str  # the cfg field switching it on
    meaning: str
    axes: tuple[int, ...] = ()  # body_velocity: the body axes of the rows
    lever_arm: str = ""  # body_velocity: the cfg field of the lever arm (IMU to the point measured) [m]
    group: str = ""
    fields: tuple[Field, ...] = ()
    values: Callable[[object], dict] = field(default=lambda config: {}, compare=False)

    @property
    def dof(self) -> int:
        """Rows of one update: the gate's degrees of freedom."""
        return len(self.sigmas)

    @property
    def counter(self) -> str:
        """Its count in Flight.counts."""
        return f"{self.name}_updates"


def stream_values(section: str, lever_arm: bool = False) -> Callable[[object], dict]:
    """The fields of a log-stream sensor (enabled, sigma, lever arm) from the configuration's ``aiding[section]``."""
    def values(config) -> dict:
        settings = (getattr(config, "aiding", None) or {}).get(section)
        out = {f"{section}_enabled": int(bool(settings and settings.enabled)),
               f"{section}_sigma": float(settings.sigma) if settings else 1.0}
        if lever_arm:
            out[f"{section}_lever_arm"] = list(settings.lever_arm or (0.0, 0.0, 0.0)) if settings else [0.0] * 3
        return out
    return values


def _zupt_values(config) -> dict:
    return {"zupt_enabled": int(config.zupt_enabled), "zupt_speed_max": config.zupt_speed_max,
            "zupt_sigma": config.zupt_sigma}


def _nhc_values(config) -> dict:
    return {"nhc_enabled": int(config.nhc_enabled), "nhc_speed_min": config.nhc_speed_min,
            "nhc_sigma_lateral": config.nhc_sigma_lateral, "nhc_sigma_vertical": config.nhc_sigma_vertical,
            "nhc_rate_max": config.nhc_rate_max, "nhc_lever_arm": list(config.nhc_lever_arm)}


#: GNSS is updated at its epochs (fly()'s epoch loop, the C's navigator_epoch), with the gate release and de-weighting
#: of filter:; its rows are the model file's own measurement, so the entry describes rather than drives that update
GNSS = AidingSensor(
    "gnss", "gnss", "gnss", "model", (), "use && factor > 0.0", "", "GNSS position and velocity at the antenna "
    "(lever arm gnss.lever_arm_m), the model file's measurement; sigmas from the receiver (gnss.quality_factor)")
ZUPT = AidingSensor(
    "zupt", "zupt", "imu", "velocity", ("cfg->zupt_sigma",) * 3, "still && speed < cfg->zupt_speed_max",
    "zupt_enabled", "zero-velocity update: the IMU detector says still and the navigator is slow", group="motion",
    fields=(Field("zupt_enabled", "int", 1, "zero-velocity updates on (1) or off (0)", key="zupt.enabled"),
            Field("zupt_speed_max", "double", 1, "ZUPT only below this navigator speed [m/s]", key="zupt.speed_max_m_s"),
            Field("zupt_sigma", "double", 1, "ZUPT sigma [m/s]", key="zupt.sigma_m_s")),
    values=_zupt_values)
NHC = AidingSensor(
    "nhc", "nhc", "imu", "body_velocity", ("cfg->nhc_sigma_lateral", "cfg->nhc_sigma_vertical"),
    "speed > cfg->nhc_speed_min && rate_norm < cfg->nhc_rate_max", "nhc_enabled",
    "non-holonomic constraint: no lateral or vertical body velocity at the constrained point (nhc.lever_arm_m)",
    axes=(1, 2), lever_arm="nhc_lever_arm", group="motion",
    fields=(Field("nhc_enabled", "int", 1, "non-holonomic constraint on (1) or off (0)", key="nhc.enabled"),
            Field("nhc_speed_min", "double", 1, "NHC only above this speed [m/s]", key="nhc.speed_min_m_s"),
            Field("nhc_sigma_lateral", "double", 1, "NHC lateral sigma [m/s]", key="nhc.sigma_lateral_m_s"),
            Field("nhc_sigma_vertical", "double", 1, "NHC vertical sigma [m/s]", key="nhc.sigma_vertical_m_s"),
            Field("nhc_rate_max", "double", 1, "NHC only below this bias-corrected angular rate [rad/s]",
                  key="nhc.rate_max_deg_s", scale=DEG),
            Field("nhc_lever_arm", "double", 3, "IMU to the point the NHC holds at (rear axle centre) in body axes [m]",
                  key="nhc.lever_arm_m")),
    values=_nhc_values)
ODOMETER = AidingSensor(
    "odometer", "odometer", "odometer", "body_velocity", ("cfg->odometer_sigma",), "fresh", "odometer_enabled",
    "wheel speed along body x at the wheel's lever arm", axes=(0,), lever_arm="odometer_lever_arm",
    fields=(Field("odometer_enabled", "int", 1, "odometer updates on (1) or off (0)", key="odometer.enabled"),
            Field("odometer_sigma", "double", 1, "odometer speed sigma [m/s]", key="odometer.sigma_m_s"),
            Field("odometer_lever_arm", "double", 3, "IMU to the odometer's wheel contact in body axes [m]",
                  key="odometer.lever_arm_m")),
    values=stream_values("odometer", lever_arm=True))
BAROMETER = AidingSensor(
    "barometer", "barometer", "barometer", "height", ("cfg->barometer_sigma",), "fresh", "barometer_enabled",
    "barometric height (on the navigator's height)",
    fields=(Field("barometer_enabled", "int", 1, "barometer updates on (1) or off (0)", key="barometer.enabled"),
            Field("barometer_sigma", "double", 1, "barometric height sigma [m]", key="barometer.sigma_m")),
    values=stream_values("barometer"))

#: every aiding sensor, in the order a covariance step tries them (the GNSS epochs come on their own)
SENSORS: tuple[AidingSensor, ...] = (GNSS, ZUPT, NHC, ODOMETER, BAROMETER)


def step_sensors(table: tuple[AidingSensor, ...] = SENSORS) -> tuple[AidingSensor, ...]:
    """The entries tried at a covariance step (all but the GNSS epochs)."""
    return tuple(s for s in table if s.stream != "gnss")


def log_sensors(table: tuple[AidingSensor, ...] = SENSORS) -> tuple[AidingSensor, ...]:
    """The entries that read a log of their own (their slot in the C is their index here)."""
    return tuple(s for s in table if s.stream not in ("gnss", "imu"))


def sensor_fields(table: tuple[AidingSensor, ...] = SENSORS) -> tuple[Field, ...]:
    """Every entry's configuration fields, in table order."""
    return tuple(f for s in table for f in s.fields)


def sensor_values(config, table: tuple[AidingSensor, ...] = SENSORS) -> dict:
    """Every entry's configuration values."""
    out: dict = {}
    for s in table:
        out.update(s.values(config))
    return out


def python_expression(expression: str) -> str:
    """A table expression (C) as Python: ``->`` read as ``.``, ``&&`` as ``and``, ``||`` as ``or``."""
    return expression.replace("->", ".").replace("&&", " and ").replace("||", " or ")


def compiled_condition(sensor: AidingSensor):
    """The entry's condition compiled for Python (evaluated over speed, still, rate_norm, fresh, cfg)."""
    return compile(python_expression(sensor.condition), f"<{sensor.name} condition>", "eval")


def sigmas(sensor: AidingSensor, cfg) -> np.ndarray:
    """The entry's row sigmas from the configuration namespace."""
    return np.array([float(eval(python_expression(s), {"__builtins__": {}}, {"cfg": cfg}))  # noqa: S307 - our table
                     for s in sensor.sigmas])


def rows(sensor: AidingSensor, spec, nav: np.ndarray, c_bn: np.ndarray, rate_body: np.ndarray, measured: float,
         cfg) -> tuple[np.ndarray, np.ndarray]:
    """z (navigator minus measurement) and H of one update of the entry's form, in the spec's blocks."""
    if sensor.form == "velocity":
        return spec.zupt_rows(nav[4:7])
    if sensor.form == "body_velocity":
        return body_velocity_rows(spec, c_bn, nav[4:7], rate_body,
                                  np.asarray(getattr(cfg, sensor.lever_arm), float) if sensor.lever_arm else None,
                                  sensor.axes, measured)
    if sensor.form == "height":
        if spec.ecef:
            return height_rows_ecef(spec, nav[7:10], measured)
        return height_rows(spec, nav[9], measured)
    raise ValueError(f"aiding sensor {sensor.name}: form {sensor.form!r} is built elsewhere or unknown")


def body_velocity_rows(spec, c_bn: np.ndarray, v_ned: np.ndarray, rate_body: np.ndarray, lever: np.ndarray | None,
                       axes: tuple[int, ...], measured: float) -> tuple[np.ndarray, np.ndarray]:
    """z = (C_n^b v + omega x l)[axes] - measured; H = [-C_n^b [v x], C_n^b][axes] (phi and velocity difference).

    With the phi-angle attitude error (C_b^n' = (I - [phi x]) C_b^n) and v' = v + dv the predicted body velocity is
    C_n^b v + C_n^b dv - C_n^b [v x] phi to first order; the lever-arm term's error (gyro bias x l) is neglected.
    """
    c_nb = c_bn.T
    skew = np.array([[0.0, -v_ned[2], v_ned[1]], [v_ned[2], 0.0, -v_ned[0]], [-v_ned[1], v_ned[0], 0.0]])
    index = list(axes)
    attitude, velocity = -(c_nb @ skew)[index], c_nb[index]
    H = np.zeros((len(index), spec.n_states))
    for block, block_rows in ((spec.blocks["attitude"], attitude), (spec.blocks["velocity"], velocity)):
        for i, a, s in zip(block.indices, block.axes, block.signs):
            H[:, i] = s * block_rows[:, a]
    body = c_nb @ v_ned
    if lever is not None:
        body = body + np.cross(rate_body, lever)
    return body[index] - measured, H


def height_rows(spec, height: float, measured: float) -> tuple[np.ndarray, np.ndarray]:
    """z = h - measured (the up error, INS minus truth); H on the position block's vertical state."""
    pos = spec.blocks["position"]
    H = np.zeros((1, spec.n_states))
    for i, a, s in zip(pos.indices, pos.axes, pos.signs):
        if a == 2:
            H[0, i] = -s  # the block's down component is s * x; the up error is minus it
    return np.array([height - measured]), H


def height_rows_ecef(spec, position: np.ndarray, measured: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`height_rows` of an ecef model: z = h(r^e) - measured; the up error is -(C_n^e's down column) . dr^e."""
    from modelgen.navigator.ecef import geodetic, ned_to_ecef

    lat, lon, h = geodetic(position)
    c_ne = ned_to_ecef(lat, lon)
    pos = spec.blocks["position"]
    H = np.zeros((1, spec.n_states))
    for i, a, s in zip(pos.indices, pos.axes, pos.signs):
        H[0, i] = -s * c_ne[a, 2]
    return np.array([h - measured]), H


class StreamCursor:
    """A log stream's samples taken at covariance steps: the latest at or before t not taken yet, once."""

    def __init__(self, time: np.ndarray, value: np.ndarray):
        self.time, self.value, self.taken = np.asarray(time, float), np.asarray(value, float), -1

    def take(self, t: float) -> tuple[bool, float]:
        """(fresh, value) at time t: fresh if a sample newer than the last taken is at or before t."""
        index = int(np.searchsorted(self.time, t, side="right")) - 1
        if index > self.taken:
            self.taken = index
            return True, float(self.value[index])
        return False, math.nan
