"""The navigator's noise parameters by maximum likelihood of its innovations with GNSS present.

A Kalman filter gives, at every update, the density it expects the innovation
from: nu ~ N(0, S), S = H P H^T + R.  The log-likelihood of a flight's
innovations,

    log L = -1/2 sum_updates (log det(2 pi S) + nu^T S^-1 nu),

is the likelihood of the noise parameters given the data (the prediction-error
decomposition; Schweppe 1965, Mehra 1970).  Its maximum over the process
noises (IMU white noises and bias driving noises) and the aiding sensors'
measurement noises is the standard estimate of those parameters: unlike a NIS
target, it weighs how large the innovations are against how large the filter
predicts them *and* how fast the filter's uncertainty grows between updates,
which is what decides its covariance once the updates stop.

Stage 5 of ``bench/navigator_tuning.py`` estimates the IMU white noises' factor
(:data:`PROCESS_NOISE`), with the measurement noises held at their stage-4 values
and the bias driving noises at the data sheet's (see :data:`PROCESS_NOISE` for
why not all of them).

The flight is the configuration's log with GNSS present everywhere (no outage
flown, no outage error computed: nothing here can see the figures an outage
schedule is judged by).  Every update tried counts, before any gate.  The
search is Nelder-Mead over the parameters' base-10 logarithms (factors on the
configured values), from the configured values.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from modelgen.navigator.config import NavigatorConfig
from modelgen.navigator.tuning import CONFIG_FIELDS, Innovations, record_innovations

#: the parameters the search can estimate: configuration key -> what setting it changes.  The two white noises
#: share one factor (one vibration environment: the data cannot tell the two apart, stage 1 of
#: bench/navigator_tuning.py), so noise.gyro_white.factor also sets noise.accel_white.factor.
PARAMETERS = ("noise.gyro_white.factor", "noise.gyro_bias_driving.factor", "noise.accel_bias_driving.factor",
              "gnss.position_variance_factor", "gnss.velocity_variance_factor",
              "nhc.sigma_lateral_m_s", "nhc.sigma_vertical_m_s", "zupt.sigma_m_s")

#: what stage 5 estimates: the white-noise factor.  The measurement noises keep the values the innovations' time
#: correlation gave them (stage 4, modelgen.navigator.tuning): every update is scored as independent here, so with
#: the measurement noises free the likelihood explains errors correlated over many updates as a tight sensor and a
#: loud IMU (on the drive: white-noise factor 60-110, NHC sigma 8 mm/s after 25 flights), which is the
#: one-update-ahead prediction it scores and not the information the updates hold.  The bias driving noises keep
#: the data sheet's values: with them free too the search walks along a ridge (15 states, 66 flights: gyro 1 ->
#: 0.05, accelerometer 1 -> 24, still moving) for a gain of 8 in log L, which is below what chance gives once the innovations'
#: correlation is counted (n updates correlated with factor f hold n / f independent ones; f is 6-35 here, and
#: twice the gain against a chi-square quantile of 2 degrees of freedom, 6.0, asks for a gain of 3 f); the
#: white-noise factor's gain is about 2,300 (bench/results/navigator_tuning_stage5_three_noises_*.log).
PROCESS_NOISE = PARAMETERS[:1]

_TIED = {"noise.gyro_white.factor": ("gyro_white", "accel_white")}


def information_criteria(log_l: float, k: int, n: int) -> dict[str, float]:
    """AIC = 2 k - 2 log L and BIC = k ln n - 2 log L of a fit with k estimated parameters on n updates."""
    return {"log_likelihood": float(log_l), "parameters": int(k), "updates": int(n),
            "aic": 2.0 * k - 2.0 * float(log_l), "bic": k * math.log(n) - 2.0 * float(log_l)}


def log_likelihood(sources: dict[str, Innovations]) -> dict[str, float]:
    """The innovations' Gaussian log-likelihood per sensor and in total: -1/2 sum(log det 2 pi S + nu^T S^-1 nu)."""
    out = {}
    for name, entry in sources.items():
        total = 0.0
        for rows in {len(s) for s in entry.S}:  # updates of one size at a time (batched determinants)
            chosen = [i for i, s in enumerate(entry.S) if len(s) == rows]
            _, logdet = np.linalg.slogdet(2.0 * math.pi * np.array([entry.S[i] for i in chosen], float))
            total += -0.5 * float(np.sum(logdet) + sum(entry.nis[i] for i in chosen))
        out[name] = total
    out["total"] = float(sum(out.values()))
    return out


#: the prefix of a model's free parameter as a key (``parameters.gnss_error_time``: the configuration's
#: parameters: entry, else the model's default given to parameter_value)
MODEL_PARAMETER = "parameters."


def parameter_value(config: NavigatorConfig, key: str, defaults: dict[str, float] | None = None) -> float:
    """The configured value of one :data:`PARAMETERS` key, or of a model parameter ``parameters.<name>``."""
    if key.startswith(MODEL_PARAMETER):
        name = key[len(MODEL_PARAMETER):]
        given = dict(config.parameters or {})
        if name in given:
            return float(given[name])
        if defaults and name in defaults:
            return float(defaults[name])
        raise KeyError(f"{key}: not set by the configuration's parameters: (and no default given)")
    if key.startswith("noise."):
        return config.noise[key.split(".")[1]].factor
    return float(getattr(config, CONFIG_FIELDS[key]))


def with_parameters(config: NavigatorConfig, values: dict[str, float]) -> NavigatorConfig:
    """The configuration with the named :data:`PARAMETERS` keys set (a noise factor also moves its SI value); a
    ``parameters.<name>`` key sets that model parameter in the configuration's parameters:."""
    noise = dict(config.noise)
    fields = {}
    model_parameters = dict(config.parameters or {})
    for key, value in values.items():
        if key.startswith(MODEL_PARAMETER):
            model_parameters[key[len(MODEL_PARAMETER):]] = float(value)
            fields["parameters"] = model_parameters
        elif key.startswith("noise."):
            for kind in _TIED.get(key, (key.split(".")[1],)):
                entry = noise[kind]
                noise[kind] = dataclasses.replace(entry, factor=value, si=entry.si / entry.factor * value)
        else:
            fields[CONFIG_FIELDS[key]] = value
    return dataclasses.replace(config, noise=noise, **fields)


@dataclass(frozen=True)
class Estimate:
    """The search's result: each parameter before and after, log-likelihoods, flights flown, convergence."""

    before: dict[str, float]
    after: dict[str, float]
    held: dict[str, float]  # the other PARAMETERS, as configured throughout the search
    log_likelihood_before: dict[str, float]
    log_likelihood_after: dict[str, float]
    flights: int
    converged: bool
    message: str


def gnss_present_innovations(inputs, spec) -> Callable[[NavigatorConfig], dict[str, Innovations]]:
    """The flight the search scores: the log flown with GNSS present everywhere, every update's innovation."""
    return lambda config: record_innovations(config, inputs, spec)[0]


def maximum_likelihood(config: NavigatorConfig, innovations: Callable[[NavigatorConfig], dict[str, Innovations]],
                       keys: tuple[str, ...] = PROCESS_NOISE, max_flights: int = 240, log10_tolerance: float = 0.02,
                       progress: Callable[[int, float, dict[str, float]], None] | None = None) -> Estimate:
    """Maximize the innovation log-likelihood over ``keys`` (factors on their configured values).

    ``innovations`` flies a configuration and returns its innovations by sensor
    (:func:`gnss_present_innovations`).  Nelder-Mead on log10 of each parameter, from the configured values, an
    initial step of a factor 3 on each; stops when the simplex is within ``log10_tolerance`` (0.02: 5 %) or after
    ``max_flights`` flights.
    """
    start = {key: parameter_value(config, key) for key in keys}
    if any(v <= 0 for v in start.values()):
        raise ValueError(f"maximum_likelihood: the search is over log10 of positive values ({start})")
    cache: dict[tuple[float, ...], dict[str, float]] = {}

    def flown(log10: np.ndarray) -> dict[str, float]:
        point = tuple(round(float(v), 6) for v in log10)
        if point not in cache:
            values = {key: start[key] * 10.0 ** v for key, v in zip(keys, point)}
            cache[point] = log_likelihood(innovations(with_parameters(config, values)))
            if progress is not None:
                progress(len(cache), cache[point]["total"], values)
        return cache[point]

    def objective(log10: np.ndarray) -> float:
        total = flown(log10)["total"]
        return -total if math.isfinite(total) else math.inf

    x0 = np.zeros(len(keys))
    simplex = np.vstack([x0] + [x0 + 0.5 * np.eye(len(keys))[i] for i in range(len(keys))])
    result = minimize(objective, x0, method="Nelder-Mead",
                      options={"initial_simplex": simplex, "xatol": log10_tolerance, "fatol": 0.5,
                               "maxfev": max_flights})
    after = {key: start[key] * 10.0 ** float(v) for key, v in zip(keys, result.x)}
    held = {key: parameter_value(config, key) for key in PARAMETERS if key not in keys}
    held.update({f"{MODEL_PARAMETER}{k}": float(v) for k, v in (config.parameters or {}).items()
                 if f"{MODEL_PARAMETER}{k}" not in keys})
    return Estimate(start, after, held, flown(x0), flown(result.x), len(cache), bool(result.success),
                    str(result.message))
