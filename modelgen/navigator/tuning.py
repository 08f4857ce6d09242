"""Measurement noise from the innovations with GNSS present: how correlated each aiding sensor's errors are.

The navigator's filter treats every aiding update as white: GNSS at 4 Hz, the
non-holonomic constraint (NHC) and the zero-velocity update (ZUPT) at every
covariance step.  If an update's errors are correlated over several updates the
filter takes each one as new information, and its covariance of what the
updates observe only indirectly (attitude, biases) shrinks too far: it is then
overconfident as soon as the updates stop (a GNSS outage).

This module measures that correlation from the innovations of a flight with
GNSS present everywhere (no simulated outage: nothing here can see an outage
error) and turns it into the factor a navigation engineer inflates R by:

* every update tried is recorded (:func:`record_innovations`, through the
  filter's ``monitor``): its time, innovation nu, innovation covariance
  S = H P H^T + R and R;
* each row is standardized, e = nu_i / sqrt(S_ii), and its autocorrelation
  rho_k = sum(e_t e_{t+k}) / sum(e_t^2) is taken over the pairs exactly k
  update steps apart (:func:`update_steps`: each gap between consecutive
  updates counted in update periods, so time tags drifting against a fixed
  grid keep every pair; the NHC and the ZUPT are used only while their
  conditions hold: a pause counts its missed periods, so pairs across it are
  not formed);
* the correlation factor is the integrated autocorrelation
  f = 1 + 2 sum_{k=1}^{K-1} rho_k, summed while the pair sums
  rho_2m + rho_2m+1 stay positive (Geyer's initial positive sequence; at
  most :data:`MAX_LAG_S`): n updates whose errors
  are correlated like this carry the information of n / f independent ones, so
  R x f gives the filter the information the updates really hold (the
  variance-inflation remedy for time-correlated measurement noise);
* the decorrelation time tau (rho first below 1/e) is stated beside it.

:func:`tune` maps the rows to the configuration keys they set (the GNSS
position and velocity variance factors, the NHC's lateral and vertical sigma,
the ZUPT sigma) and returns each new value with the statistic that gives it;
:func:`consistency` states each sensor's NIS against chi-square (mean against
the row count, fraction inside the 95 % quantile).  ``python
bench/navigator_tuning.py --correlation`` prints both for the built-in drive.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2

from modelgen.navigator.config import NavigatorConfig

#: longest lag of the autocorrelation [s]
MAX_LAG_S = 20.0


#: the measurement-noise keys the innovations set (stage 4) -> the NavigatorConfig field each one is
CONFIG_FIELDS = {"gnss.position_variance_factor": "gnss_position_variance_factor",
                 "gnss.velocity_variance_factor": "gnss_velocity_variance_factor",
                 "nhc.sigma_lateral_m_s": "nhc_sigma_lateral", "nhc.sigma_vertical_m_s": "nhc_sigma_vertical",
                 "zupt.sigma_m_s": "zupt_sigma"}


@dataclass
class Innovations:
    """Every update of one aiding sensor tried in a flight, in time order."""

    source: str
    time: list[float] = field(default_factory=list)
    nu: list[np.ndarray] = field(default_factory=list)
    S: list[np.ndarray] = field(default_factory=list)
    r: list[np.ndarray] = field(default_factory=list)
    nis: list[float] = field(default_factory=list)

    def standardized(self) -> np.ndarray:
        """(updates, rows): nu_i / sqrt(S_ii)."""
        nu = np.array(self.nu, float)
        diag = np.array([np.diag(s) for s in self.S], float)
        return nu / np.sqrt(diag)


class InnovationRecorder:
    """The filter's monitor: keeps every update's innovation by source."""

    def __init__(self) -> None:
        self.sources: dict[str, Innovations] = {}

    def __call__(self, source: str, time: float, nu: np.ndarray, S: np.ndarray, r: np.ndarray, nis: float) -> None:
        entry = self.sources.setdefault(source, Innovations(source))
        entry.time.append(float(time))
        entry.nu.append(np.array(nu, float))
        entry.S.append(np.array(S, float))
        entry.r.append(np.array(r, float))
        entry.nis.append(float(nis))


def gnss_present(config: NavigatorConfig) -> NavigatorConfig:
    """The configuration with no simulated outage (GNSS present wherever the log has it); all else unchanged."""
    return dataclasses.replace(config, outage_schedule=None, outage_windows=None)


def record_innovations(config: NavigatorConfig, inputs, spec) -> tuple[dict[str, Innovations], object]:
    """Fly the log with GNSS present everywhere (the Python navigator) and record every update's innovation."""
    from modelgen.navigator.navigator import fly

    recorder = InnovationRecorder()
    flight = fly(gnss_present(config), inputs, spec, monitor=recorder)
    return recorder.sources, flight


def update_period(time: np.ndarray) -> float:
    """The sensor's update period: the median spacing of consecutive updates [s]."""
    return float(np.median(np.diff(time)))


def update_steps(time: np.ndarray, period: float | None = None) -> np.ndarray:
    """Each update's step number: 0 at the first, then each gap to the one before in update periods T
    (``period``, by default the sensor's median spacing, :func:`update_period`), rounded, at least 1.

    Counted gap by gap, not as (t - t_0) / T: a receiver's epochs drift against any fixed grid over a drive
    (the built-in drive's 4-Hz epochs are 0.11 s off t_0 + n T after 9 minutes) and the NHC's covariance
    steps are sometimes half a period apart; a gap where a sensor did not update counts its missed periods.
    The one numbering of updates that :func:`lagged_pairs` (stage 4's autocorrelation) and the thinned
    composite log-likelihood (:func:`modelgen.navigator.likelihood.thinned_log_likelihood`) both use."""
    time = np.asarray(time, float)
    if len(time) < 2:
        return np.zeros(len(time), dtype=np.int64)
    period = update_period(time) if period is None else float(period)
    gaps = np.maximum(1, np.round(np.diff(time) / period).astype(np.int64))
    return np.concatenate([[0], np.cumsum(gaps)])


def lagged_pairs(time: np.ndarray, x: np.ndarray, period: float, max_lag_s: float = MAX_LAG_S):
    """For k = 0 .. max lag: (k, x_t, x_{t+k}) over the samples of ``x`` exactly k update steps apart.

    The samples are numbered by :func:`update_steps` (the gaps between consecutive updates counted in periods
    T), so every sample is kept however far its time tag drifts from t_0 + n T, and a gap in the updates (its
    missed periods counted) leaves out the pairs across it instead of pairing samples at other lags."""
    x = np.asarray(x, float)
    steps = update_steps(time, period)
    where = np.full(int(steps[-1]) + 1 if len(steps) else 0, -1, dtype=np.int64)  # step -> sample, or -1
    where[steps] = np.arange(len(steps))
    for k in range(int(round(max_lag_s / period)) + 1):
        partner = np.where(steps + k < len(where), where[np.minimum(steps + k, len(where) - 1)], -1)
        ok = partner >= 0
        yield k, x[ok], x[partner[ok]]


def autocorrelation(time: np.ndarray, e: np.ndarray, period: float, max_lag_s: float = MAX_LAG_S) -> np.ndarray:
    """rho_k, k = 0 .. max lag, of a standardized series sampled at ``time`` (pairs exactly k periods apart).

    Zero-mean by the filter's assumption (not demeaned: a persistent offset is correlation too).  A lag with fewer
    than 10 pairs is NaN.
    """
    rho = np.full(int(round(max_lag_s / period)) + 1, np.nan)
    rho[0] = 1.0
    for k, a, b in lagged_pairs(time, e, period, max_lag_s):
        if k and len(a) >= 10:  # normalised by the energy of the pairs' own samples (unbiased over gappy series)
            rho[k] = float(np.sum(a * b) / math.sqrt(np.sum(a**2) * np.sum(b**2)))
    return rho


def correlation_factor(rho: np.ndarray) -> tuple[float, int]:
    """(f, K): f = 1 + 2 sum_{k=1}^{K-1} rho_k, Geyer's initial positive sequence.

    The lags are summed in pairs Gamma_m = rho_2m + rho_2m+1 while Gamma_m > 0 (and both lags have pairs): the
    integrated autocorrelation time in update periods, the variance inflation of a mean over correlated samples.
    K is the first lag not summed.
    """
    total, k = -1.0, 0
    while k + 1 < len(rho) and math.isfinite(rho[k]) and math.isfinite(rho[k + 1]) and rho[k] + rho[k + 1] > 0.0:
        total += 2.0 * (rho[k] + rho[k + 1])
        k += 2
    return max(total, 1.0), k


def decorrelation_time(rho: np.ndarray, period: float) -> float:
    """The lag at which rho first falls below 1/e [s] (linear between lags); inf if it never does."""
    threshold = math.exp(-1.0)
    for k in range(1, len(rho)):
        if math.isfinite(rho[k]) and rho[k] < threshold:
            before = rho[k - 1]
            return period * (k - 1 + (before - threshold) / (before - rho[k]))
    return math.inf


def autocovariance(time: np.ndarray, x: np.ndarray, period: float, max_lag_s: float = MAX_LAG_S) -> np.ndarray:
    """C_k, k = 0 .. max lag, of a series sampled at ``time``: mean of x_t x_{t+k} over the pairs exactly k periods
    apart (:func:`lagged_pairs`; not demeaned, as :func:`autocorrelation`); NaN where a lag has fewer than 10 pairs."""
    out = np.full(int(round(max_lag_s / period)) + 1, np.nan)
    for k, a, b in lagged_pairs(time, x, period, max_lag_s):
        if len(a) >= 10:
            out[k] = float(np.mean(a * b))
    return out


@dataclass(frozen=True)
class MarkovFit:
    """A first-order Gauss-Markov error fitted to an autocovariance: C_k = sigma^2 exp(-k T / tau), k >= 1."""

    tau_s: float
    sigma: float
    lags: int  # lags used (1 .. lags)
    white_sigma: float  # sqrt(C_0 - sigma^2): the rest of the lag-0 variance (white, and the filter's own share)


def markov_fit(cov: np.ndarray, period: float, floor: float = 0.1) -> MarkovFit:
    """Fit log C_k = log sigma^2 - k T / tau by least squares over k = 1 .. K, K the last lag before C_k first falls
    below ``floor`` x C_1 (or is not positive).  Lag 0 is left out: it holds the white noise too.

    The starting point of the shaping filter's identification (:func:`markov_start`); the estimate itself is the
    likelihood's (:func:`modelgen.navigator.likelihood.maximum_likelihood`)."""
    cov = np.asarray(cov, float)
    lags = []
    for k in range(1, len(cov)):
        if not (math.isfinite(cov[k]) and cov[k] > 0.0 and cov[k] >= floor * cov[1]):
            break
        lags.append(k)
    if len(lags) < 2:
        raise ValueError("markov_fit: the autocovariance is not positive over two lags (no correlated error to fit)")
    k = np.array(lags, float)
    slope, intercept = np.polyfit(k * period, np.log(cov[lags]), 1)
    if not slope < 0.0:
        raise ValueError("markov_fit: the autocovariance does not decay")
    sigma2 = math.exp(intercept)
    return MarkovFit(-1.0 / slope, math.sqrt(sigma2), len(lags), math.sqrt(max(float(cov[0]) - sigma2, 0.0)))


def markov_start(sources: dict[str, Innovations], spec, kind: str = "position") -> dict:
    """The Gauss-Markov fit of each GNSS ``kind`` row's innovations (metres) and of their mean autocovariance.

    ``sources``: a flight's innovations with GNSS present, flown with that row's noise white (R not inflated).
    Returns {"rows": {label: MarkovFit}, "pooled": MarkovFit, "period_s": T}."""
    entry = sources["gnss"]
    time = np.array(entry.time)
    period = update_period(time)
    nu = np.array(entry.nu, float)
    axes = ("north", "east", "down")
    rows, covs = {}, []
    for i, r in enumerate(spec.gnss_rows):
        if r.kind != kind:
            continue
        cov = autocovariance(time, nu[:, i], period)
        covs.append(cov)
        rows[f"{kind} {axes[r.axis]}"] = markov_fit(cov, period)
    return {"rows": rows, "pooled": markov_fit(np.mean(covs, axis=0), period), "period_s": period}


@dataclass(frozen=True)
class RowStatistic:
    """One innovation row's whiteness: its update period, tau, correlation factor and the lags summed."""

    source: str
    row: int
    label: str
    updates: int
    period_s: float
    tau_s: float
    factor: float
    lags: int
    rho: tuple[float, ...]  # rho_1 .. rho_5


def row_statistics(sources: dict[str, Innovations], labels: dict[str, list[str]]) -> list[RowStatistic]:
    """Every recorded row's statistic (``labels``: the row names of each source)."""
    out = []
    for name, entry in sources.items():
        if len(entry.time) < 20:
            continue
        time = np.array(entry.time)
        period = update_period(time)
        e = entry.standardized()
        for i in range(e.shape[1]):
            rho = autocorrelation(time, e[:, i], period)
            f, lags = correlation_factor(rho)
            out.append(RowStatistic(name, i, labels.get(name, [str(j) for j in range(e.shape[1])])[i], len(time),
                                    period, decorrelation_time(rho, period), f, lags,
                                    tuple(float(v) for v in rho[1:6])))
    return out


def row_labels(spec) -> dict[str, list[str]]:
    """The row names of each aiding sensor's update: GNSS from the model's rows, NHC lateral/vertical, ZUPT N/E/D."""
    axes = ("north", "east", "down")
    return {"gnss": [f"{r.kind} {axes[r.axis]}" for r in spec.gnss_rows],
            "nhc": ["lateral", "vertical"], "zupt": list(axes), "odometer": ["speed"], "barometer": ["height"]}


@dataclass(frozen=True)
class Tuned:
    """One configuration number set from the innovations: key, value before and after, and the statistic."""

    key: str
    before: float
    after: float
    factor: float  # the variance factor applied (the mean correlation factor of its rows)
    rows: tuple[str, ...]
    statistic: str


def _mean_factor(stats: list[RowStatistic], source: str, rows: list[int] | None = None) -> tuple[float, list]:
    chosen = [s for s in stats if s.source == source and (rows is None or s.row in rows)]
    return (float(np.mean([s.factor for s in chosen])) if chosen else 1.0), chosen


def tune(config: NavigatorConfig, stats: list[RowStatistic], spec) -> list[Tuned]:
    """The configuration numbers the correlation factors set (R x f: a sigma x sqrt(f), a variance factor x f)."""
    out = []

    def describe(chosen: list[RowStatistic]) -> str:
        return "; ".join(f"{s.label}: tau {s.tau_s:.2f} s, f {s.factor:.2f} ({s.lags - 1} lags of {s.period_s:.2f} s)"
                         for s in chosen)

    position = [i for i, r in enumerate(spec.gnss_rows) if r.kind == "position"]
    velocity = [i for i, r in enumerate(spec.gnss_rows) if r.kind == "velocity"]
    for key, rows, before in (("gnss.position_variance_factor", position, config.gnss_position_variance_factor),
                              ("gnss.velocity_variance_factor", velocity, config.gnss_velocity_variance_factor)):
        f, chosen = _mean_factor(stats, "gnss", rows)
        if chosen:
            out.append(Tuned(key, before, before * f, f, tuple(s.label for s in chosen), describe(chosen)))
    for key, source, rows, before in (("nhc.sigma_lateral_m_s", "nhc", [0], config.nhc_sigma_lateral),
                                      ("nhc.sigma_vertical_m_s", "nhc", [1], config.nhc_sigma_vertical),
                                      ("zupt.sigma_m_s", "zupt", None, config.zupt_sigma)):
        f, chosen = _mean_factor(stats, source, rows)
        if chosen:
            out.append(Tuned(key, before, before * math.sqrt(f), f, tuple(s.label for s in chosen), describe(chosen)))
    return out


def apply(config: NavigatorConfig, tuned: list[Tuned]) -> NavigatorConfig:
    """The configuration with the tuned numbers in place."""
    return dataclasses.replace(config, **{CONFIG_FIELDS[t.key]: t.after for t in tuned})


@dataclass(frozen=True)
class SensorNis:
    """One sensor's NIS against chi-square with its row count: mean (expected = rows), fraction inside 95 %."""

    source: str
    rows: int
    updates: int
    mean: float
    median: float
    inside_95: float


def consistency(sources: dict[str, Innovations]) -> list[SensorNis]:
    """Each sensor's NIS statistics (every update tried, before any gate or de-weighting)."""
    out = []
    for name, entry in sources.items():
        if not entry.nis:
            continue
        nis = np.array(entry.nis)
        rows = len(entry.nu[0])
        out.append(SensorNis(name, rows, len(nis), float(nis.mean()), float(np.median(nis)),
                             float(np.mean(nis <= chi2.ppf(0.95, rows)))))
    return out


def correlation_tuning(config: NavigatorConfig, inputs, spec) -> dict:
    """Stage 4 end to end, with GNSS present everywhere: record, measure, tune, fly again, NIS before and after.

    Also measures the correlation factors of the tuned flight (a second pass would multiply by them again; they
    are stated, not applied: the tuning is one pass from the configuration's filter).
    """
    labels = row_labels(spec)
    sources, _ = record_innovations(config, inputs, spec)
    stats = row_statistics(sources, labels)
    tuned = tune(config, stats, spec)
    after_config = apply(config, tuned)
    sources_after, _ = record_innovations(after_config, inputs, spec)
    return {
        "configuration": config.path, "model": spec.name, "max_lag_s": MAX_LAG_S,
        "rows_before": [dataclasses.asdict(s) for s in stats],
        "tuned": [dataclasses.asdict(t) for t in tuned],
        "nis_before": [dataclasses.asdict(c) for c in consistency(sources)],
        "nis_after": [dataclasses.asdict(c) for c in consistency(sources_after)],
        "rows_after": [dataclasses.asdict(s) for s in row_statistics(sources_after, labels)],
    }


def format_result(result: dict) -> str:
    """The stage-4 result as the text the bench prints."""
    lines = [f"stage 4: {result['configuration']} ({result['model']}), GNSS present everywhere, no outage flown",
             "innovation rows (standardized nu / sqrt(S_ii)), before tuning:",
             f"{'sensor':8} {'row':18} {'updates':>7} {'period_s':>8} {'tau_s':>6} {'f':>7} {'lags':>5}  rho_1..5"]
    for s in result["rows_before"]:
        lines.append(f"{s['source']:8} {s['label']:18} {s['updates']:7d} {s['period_s']:8.3f} {s['tau_s']:6.2f} "
                     f"{s['factor']:7.2f} {s['lags']:5d}  " + " ".join(f"{v:.2f}" for v in s["rho"]))
    lines.append("tuned (R x f: a variance factor x f, a sigma x sqrt(f); f the mean over the key's rows):")
    for t in result["tuned"]:
        lines.append(f"  {t['key']}: {t['before']:.4g} -> {t['after']:.4g}  (f {t['factor']:.2f}; {t['statistic']})")
    for name in ("before", "after"):
        lines.append(f"NIS {name} (chi-square: mean = rows, 95 % inside):")
        for c in result[f"nis_{name}"]:
            lines.append(f"  {c['source']:8} rows {c['rows']}  updates {c['updates']:5d}  mean {c['mean']:7.2f}  "
                         f"median {c['median']:6.2f}  inside 95 % {100 * c['inside_95']:5.1f} %")
    lines.append("correlation factors of the tuned flight (stated, not applied):")
    lines.append("  " + "; ".join(f"{s['source']} {s['label']} {s['factor']:.1f}" for s in result["rows_after"]))
    return "\n".join(lines)
