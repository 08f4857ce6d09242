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

Stage 7 picks between its fixed points (it has more than one) by
:func:`thinned_log_likelihood`, a composite likelihood that keeps about one
innovation per integrated autocorrelation time of each row, so that each sensor
weighs by the information its updates hold and not by how often it updates.

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
from modelgen.navigator.tuning import (CONFIG_FIELDS, Innovations, record_innovations, row_statistics,
                                       update_steps)

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


@dataclass(frozen=True)
class ThinnedRow:
    """One measurement row's share of the thinned composite log-likelihood (:func:`thinned_log_likelihood`)."""

    source: str
    row: int
    step: int  # k: every k-th common epoch is kept (ceil of the largest f over the candidates)
    factors: dict[str, float]  # each candidate's integrated autocorrelation f of the row (stage 4's statistic)
    epochs: int  # the common epochs: every candidate has an update of this sensor there
    score: dict[str, float]  # candidate -> mean over the k offsets of the kept epochs' log densities (= sum / k)
    first_offset: dict[str, float]  # candidate -> the sum over the epochs at offset 0 (every k-th from the first)
    kept_first_offset: int  # how many epochs offset 0 keeps
    difference_variance: dict[str, float]  # "a - b" -> variance of one thinned draw of the difference (kept terms
    # independent: epochs / k x the per-epoch variance of l_a - l_b)


@dataclass(frozen=True)
class ThinnedScore:
    """The thinned composite log-likelihood of several candidates scored on the same epochs."""

    rows: tuple[ThinnedRow, ...]
    total: dict[str, float]  # candidate -> the statistic (sum over the rows of ThinnedRow.score)
    by_source: dict[str, dict[str, float]]  # candidate -> sensor -> its rows' share
    first_offset_total: dict[str, float]  # candidate -> sum over the rows of ThinnedRow.first_offset
    difference_standard_error: dict[str, float]  # "a - b" -> sqrt of the rows' summed difference variances
    left_out: tuple[str, ...]  # sensors not scored (absent from a candidate, or fewer than 20 updates in one)


def thinned_log_likelihood(candidates: dict[str, dict[str, Innovations]],
                           steps: dict[tuple[str, int], int] | None = None) -> ThinnedScore:
    """A correlation-aware comparison of candidate filters flown on the same data: the composite Gaussian
    log-likelihood of every row's innovations thinned to about one per integrated autocorrelation time.

    What.  ``candidates``: name -> the innovations of one flight by sensor (:func:`tuning.record_innovations`),
    every candidate flown on the same log.  For each row i of each sensor:

    * f_c, the integrated autocorrelation of the row's standardized innovations in candidate c's flight
      (:func:`modelgen.navigator.tuning.row_statistics`, stage 4's statistic), and k = ceil(max_c f_c), the same
      k for every candidate (``steps`` gives k per (sensor, row) instead, for tests);
    * the common epochs: the update times every candidate has for that sensor (the NHC and the ZUPT are used
      only while conditions on the navigator's own state hold, so two flights need not update at the same
      steps), each numbered by its update step n (:func:`modelgen.navigator.tuning.update_steps`: the gaps
      counted in update periods, the numbering stage 4's autocorrelation uses too);
    * at each, candidate c's Gaussian log density of the row, l = -1/2 (log 2 pi S_ii + nu_i^2 / S_ii), with
      its own innovation and its own innovation covariance;
    * offset j = 0 .. k-1 keeps the epochs whose step n is j mod k (two kept epochs at least k steps
      apart), the same epochs for every candidate; the row's score is the mean over the k
      offsets of the kept epochs' sum, which is the sum over every common epoch divided by k.

    The statistic is the sum of the rows' scores (``total``); offset 0 alone (``first_offset_total``) and the
    standard error of each pairwise difference of one thinned draw (kept terms taken as independent) are
    stated beside it.

    Why.  The white log-likelihood (:func:`log_likelihood`) sums every update as if independent, so a sensor
    weighs by its update count: the NHC at 10 Hz, whose errors are correlated over many updates, outweighs
    the GNSS rows, whose errors are correlated too but which update less often, by its number of updates
    rather than by the information they hold.  n updates whose errors are correlated with integrated
    autocorrelation f hold about n / f independent ones -- the premise of R x f (stage 4) and of the chance
    threshold in :data:`PROCESS_NOISE`'s note.  Keeping one update per k >= f makes the kept terms about
    independent, so each row enters with its effective number of innovations, and a composite likelihood of
    about independent terms is what a sum of log densities is the likelihood of.  Each kept term is the log
    score of the candidate's predicted density for that row -- a strictly proper scoring rule, largest in
    expectation for the density that matches the data -- and every candidate is scored on the identical
    epochs, so the comparison is paired on the same measurements.  k is the largest f of the candidates so
    that the thinning is long enough for all of them (a candidate whose own innovations look white there does
    not earn its row more weight).  The mean over the k offsets removes the arbitrary choice of the first
    kept epoch (it is the expectation of the one-offset statistic over a uniformly drawn offset).  Marginal
    rows, not the joint density of an update, because the rows of one sensor decorrelate at different rates.
    What it does not change: each kept innovation is still the filter's one-update-ahead prediction from
    every update before it, kept or not.
    """
    names = list(candidates)
    if not names:
        raise ValueError("thinned_log_likelihood: no candidates")
    factors: dict[tuple[str, int], dict[str, float]] = {}
    for name in names:
        for st in row_statistics(candidates[name], {}):
            factors.setdefault((st.source, st.row), {})[name] = st.factor
    sensors = [s for s in candidates[names[0]] if all(s in candidates[c] for c in names)]
    left_out = sorted({s for c in names for s in candidates[c]} - set(sensors))
    pairs = [(a, b) for i, a in enumerate(names) for b in names[i + 1:]]
    rows: list[ThinnedRow] = []
    for source in sensors:
        n_rows = len(candidates[names[0]][source].nu[0]) if candidates[names[0]][source].nu else 0
        keys = [(source, i) for i in range(n_rows)]
        if steps is None and not all(len(factors.get(key, {})) == len(names) for key in keys):
            left_out.append(source)  # fewer than 20 updates in some candidate: no f there
            continue
        # the common epochs (microsecond keys), each candidate's index of them
        index: dict[str, dict[int, int]] = {}
        for name in names:
            keys_us = np.round(np.asarray(candidates[name][source].time, float) * 1e6).astype(np.int64)
            index[name] = {}
            for i, key in enumerate(keys_us):
                index[name].setdefault(int(key), i)  # the first update at a time, should there be two
        common = sorted(set.intersection(*(set(index[name]) for name in names)))
        if len(common) < 2:
            left_out.append(source)
            continue
        time = np.array(common, float) * 1e-6
        step = update_steps(time)
        terms = {}
        for name in names:
            entry = candidates[name][source]
            chosen = [index[name][key] for key in common]
            nu = np.array([entry.nu[i] for i in chosen], float)
            var = np.array([np.diag(entry.S[i]) for i in chosen], float)
            terms[name] = -0.5 * (np.log(2.0 * math.pi * var) + nu**2 / var)  # (epochs, rows)
        for i in range(n_rows):
            key = (source, i)
            k = int(steps[key]) if steps is not None else max(1, math.ceil(max(factors[key].values())))
            offset = step % k
            score = {name: float(np.sum(terms[name][:, i])) / k for name in names}
            first = {name: float(np.sum(terms[name][offset == 0, i])) for name in names}
            variance = {}
            for a, b in pairs:
                d = terms[a][:, i] - terms[b][:, i]
                variance[f"{a} - {b}"] = float(np.var(d, ddof=1)) * len(d) / k if len(d) > 1 else 0.0
            rows.append(ThinnedRow(source, i, k, dict(factors.get(key, {})), int(len(step)), score, first,
                                   int(np.sum(offset == 0)), variance))
    total = {name: float(sum(r.score[name] for r in rows)) for name in names}
    by_source = {name: {s: float(sum(r.score[name] for r in rows if r.source == s))
                        for s in dict.fromkeys(r.source for r in rows)} for name in names}
    first_total = {name: float(sum(r.first_offset[name] for r in rows)) for name in names}
    spread = {f"{a} - {b}": math.sqrt(sum(r.difference_variance[f"{a} - {b}"] for r in rows)) for a, b in pairs}
    return ThinnedScore(tuple(rows), total, by_source, first_total, spread, tuple(left_out))
