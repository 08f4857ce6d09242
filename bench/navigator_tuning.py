#!/usr/bin/env python
"""Tuning the replay navigator's noise factors from innovation consistency (issue 13, item 4).

The built-in drive is flown with GNSS present everywhere (no simulated
outages) and without the NIS gate, for a grid of one common multiplying factor
on the data-sheet white noises (gyro angle random walk and accelerometer
velocity random walk together: one vibration environment; a 4 x 4 grid of
separate factors showed a valley along which the two trade off against each
other, so the data cannot tell them apart).  For each flight the score is the median NIS of the 6-row GNSS update
against the chi-square median for 6 degrees of freedom (5.35): a consistent
filter has its innovations as large as it predicts them.  The factor with the
median NIS closest to 5.35 (in ratio) is chosen; then, with it, the
non-holonomic constraint's sigma is chosen the same way from the NIS of the
2-row NHC update (chi-square median for 2 degrees of freedom, 1.39).

Stage 3 (the generated C navigator, which flies identically and 100 times
faster) chooses the NHC's angular-rate limit and the NIS gate probability,
again with GNSS everywhere, by the horizontal RMS against the receiver's own
solution and the number of de-weighted GNSS epochs.

Stage 4 (``--correlation [CONFIG]``, issue 26 item 4): the aiding updates' time
correlation, measured from the innovations of one flight with GNSS present
everywhere (:mod:`modelgen.navigator.tuning`): per row the decorrelation time
and the correlation factor f (integrated autocorrelation), which set R x f for
the GNSS position and velocity rows (gnss.position/velocity_variance_factor)
and sigma x sqrt(f) for the NHC and ZUPT; then the same flight again with the
tuned numbers and every sensor's NIS against chi-square.  Run it on the
configuration as it was before stage 4 (the tuned keys at 1 / their stage-2
values): it measures from that filter.

Stage 5 (``--likelihood [CONFIG]``): the IMU white noises' shared factor at the
maximum of the innovations' Gaussian log-likelihood of the GNSS-present flight
(:mod:`modelgen.navigator.likelihood`), searched from the configuration's value
(``--all``: every noise parameter, to see why the others are held).

Stage 6 (``--markov [CONFIG] [--json FILE]``): the shaping filter for the GNSS position's time-correlated
error (model ins_gnss24_gm_nav, configuration replay_drive_0708_gm.yaml; docs/replay-configuration.md,
"Time-correlated GNSS errors").  The method and the decision, fixed before any outage was flown:

1. start: the 21-state configuration flown with GNSS present and the position rows' R white (variance
   factor 1); the autocovariance C_k of each position innovation row (metres) is fitted with
   sigma_e^2 exp(-k T / tau) over lags 1 .. K (tuning.markov_fit; lag 0 holds the white noise): tau and
   sigma_e of the mean autocovariance of the three rows start the search;
2. estimate: the maximum of the innovations' log-likelihood with GNSS present (likelihood.maximum_likelihood)
   over the Gauss-Markov tau, sigma_e and the white-noise factor together (the white-noise factor was
   estimated with R x 13.4 and is re-estimated with the model that replaces that inflation), the position
   R white (factor 1), every other number the 21-state configuration's;
3. decision: the augmented model replaces R x f if its AIC = 2 k - 2 log L and its BIC = k ln n - 2 log L
   (n = updates of every sensor) are both lower than the 21-state configuration's at its own estimates,
   k counting the numbers estimated from this drive's innovations that the two do not share
   (21 states: the white-noise factor and the position variance factor, k = 2; 24 states: the
   white-noise factor, tau and sigma_e, k = 3);
4. then the whiteness of the new position innovations (stage 4's statistics) and every sensor's NIS.

Stage 6b (``--markov-check [STAGE6_JSON] [--json FILE]``): stage 6's search drove sigma_e to the boundary
(0.4 mm, tau unbounded): its gain in log L over the 21-state configuration came from R at its white value,
not from the states.  The 21-state configuration's R x f is not a likelihood estimate, so the decision is
taken again against the 21-state model at its own maximum likelihood with the position R white (the
white-noise factor, k = 1), beside a profile of log L over sigma_e at tau = 2 s (stage 4's decorrelation
time): the augmented model is adopted only if it beats both 21-state configurations on AIC and BIC.  This
check was added after stage 6's likelihoods were seen and before any outage was flown.

Stage 7 (``--fixed-point [CONFIG] [--json FILE]``, issue 26): stages 4 and 5 to a fixed point.  Each was run
once, from stage 1's filter (white-noise factor 7), and they do not agree with each other: stage 4's f was
measured on a filter with other noise numbers than the shipped one (with the position R white, the white-noise
factor's maximum likelihood is 39.4 and the position innovations' f there is 1.9-3.6, neither 1 nor 13.4).
The method and the decision, written before any outage was flown with its result:

1. start: the shipped configuration (CONFIG, or both built-in ones, 15 and 21 states, in two processes);
2. iterate, with GNSS present everywhere (no outage flown, no outage error computed):
   a. stage 4 on the current filter's own innovations: per row the integrated autocorrelation f of the
      standardized innovations (:func:`modelgen.navigator.tuning.row_statistics`), and each stage-4 key set to
      its white value (:data:`STAGE4_FROM`: variance factors 1, NHC 0.03 m/s, ZUPT 0.02 m/s) x f (a sigma x
      sqrt(f)), f the mean over the key's rows (:func:`modelgen.navigator.tuning.tune`) -- the factor on the
      white R, not a further factor on the current one;
   b. stage 5 given those numbers: the white-noise factor at the maximum of the innovations' Gaussian
      log-likelihood (:func:`modelgen.navigator.likelihood.log_likelihood`, every sensor), a 1-D bounded search
      (scipy.optimize.minimize_scalar, Brent) over log10 of the factor within a factor 10**0.25 either side of
      the current value (moved on if the maximum is at a bound), to 0.004 in log10 (1 %);
   c. stop when every stage-4 number and the white-noise factor change by less than 2 % (relative) from one
      iteration to the next (:data:`FIXED_POINT_TOLERANCE`), or after :data:`FIXED_POINT_ITERATIONS`
      iterations (reported as not converged);
3. decision: the shipped numbers become the last iterate -- a filter whose R factor (and NHC/ZUPT sigma) is
   the correlation its own innovations show and whose white-noise factor is the maximum-likelihood estimate
   given that R -- whatever the outage schedules then show; the correlation factors at that point are stated
   beside the numbers (the residual of the fixed point), with log L, every sensor's NIS and each row's
   whiteness.  The outage schedules are flown (``modelgen replay``) only after the numbers are written, and
   the numbers are not changed after.

4. second start (``--both-starts``; added after the first start's fixed point was shipped and its outages
   flown, before this rule's choice was flown): the same iteration from the white start (the stage-4 keys at
   their white values, the configuration's white-noise factor).  The fixed point is not unique: from there the
   15-state iteration settles at R_pos x 41 and NHC sigmas of 0.04 m/s instead of R_pos x 20.5 and 0.07/0.17.
   Of the converged fixed points, the one with the higher innovations log-likelihood (GNSS present, every
   sensor) was shipped -- a choice the innovations make, not the outages.  Its known weakness (seen after the
   chosen point was flown, so not acted on by that run): the white log-likelihood counts correlated
   innovations as independent and so favours the point with the tighter NHC (docs/replay-configuration.md,
   "Two starts").

5. the selector, replacing step 4's (written and committed before it was computed on any fixed point, and so
   before the outages of its choice were flown): each converged fixed point is flown once more with GNSS
   present (the Python navigator, every update recorded), and the one with the highest thinned composite
   log-likelihood (:func:`modelgen.navigator.likelihood.thinned_log_likelihood`) is shipped: per measurement
   row, the Gaussian log density of the row's innovation under the point's own S_ii, on the epochs every
   point has, thinned to every k-th (k = ceil of the largest integrated autocorrelation f of that row over
   the points, the same k and the same epochs for every point), averaged over the k offsets.  Each row then
   weighs by the about n / f independent innovations it holds (the premise of R x f) instead of by its
   update count.  The white log-likelihood is printed beside it, and the offset-0 value and the standard
   error of the difference (the kept terms taken as independent) are stated, not used.  Whatever it picks is
   shipped, whatever the outage schedules then show.  On the built-in drive (stage 8,
   bench/results/navigator_tuning_stage8_selector.txt) it picks the white start's point for both models:
   15 states 2421.5 against 2405.0 (the white log-likelihood picked the same), 21 states 2791.4 against
   2756.7 (the white log-likelihood picked the first start's point, which that configuration held until then).
   Stage 9 (bench/results/navigator_tuning_stage9_*): the same iteration and selector after stage 4 was made to
   pair every update (tuning.lagged_pairs numbers the updates by their gaps counted in periods,
   tuning.update_steps, instead of putting them on the grid t_0 + n T, off which the drift of the GNSS epochs
   had left about half of them).  Both starts now reach the same point within 0.8 % (inside the 2 %
   tolerance), and the thinned score picks the white start's for both models (15 states 8598.3 against
   8594.9, 21 states 9325.3 against 9321.0; the white log-likelihood picks the same): 15 states R_pos x 21.0,
   R_vel x 9.20, NHC 0.0409 / 0.0447 m/s, ZUPT 0.150 m/s, factor 36.7; 21 states R_pos x 15.9, R_vel x 4.86,
   NHC 0.0414 / 0.0449 m/s, ZUPT 0.227 m/s, factor 34.1.

Stage 10 (``--lever-arm [CONFIG ...] [--json FILE]``, issue 26): where the non-holonomic constraint holds.  The
constraint was applied at the IMU (no lever arm) and only below 10 deg/s of angular rate, because the rear axle's
distance from the IMU was not known; with a forward offset x the IMU's true lateral velocity is about omega_z x.
The method and the decisions, written before the fit was run:

1. fit: each configuration flown with GNSS present everywhere (the Python navigator, no outage flown, no outage
   error computed), the NHC tried at every covariance step above nhc.speed_min_m_s whatever the rate (rate limit
   off) with no lever arm and a sigma of :data:`LEVER_PROBE_SIGMA` (its updates then move nothing: the body
   velocity is the GNSS/INS solution's own); its recorded innovations are the IMU's body lateral and vertical
   velocity, and with the bias-corrected gyro rate of the same sample they give the lever arm l (IMU to the
   constrained point) by least squares (:func:`modelgen.navigator.lever_fit.fit`: v_y = omega_x l_z - omega_z l_x,
   v_z = omega_y l_x - omega_x l_y, from v_point = v_imu + omega x l = 0 laterally and vertically, with a speed
   term and a constant per row for a residual boresight misalignment), the Newey-West standard error over 5 s;
   the same fit on each half of the drive (residential streets, parking lot) as a check that l is one constant;
2. decision: a component is set in nhc.lever_arm_m if it is significant (|estimate| > 3 Newey-West standard
   errors) and physically plausible (within 5 m: a car's rear axle from a roof or console IMU), else it stays 0;
3. then nhc.rate_max_deg_s again by stage 3's criterion (the C navigator, GNSS everywhere, the configured gate:
   median GNSS NIS over the grid 1e9 (no limit) / 20 / 10 / 5 deg/s), the rule made explicit: the largest limit
   (the most NHC updates) whose median GNSS NIS is within :data:`RATE_LIMIT_NIS_MARGIN` of the grid's lowest (on
   stage 3's numbers, 7.1 / 6.4 / 6.2 / 6.1, it gives stage 3's 10 deg/s); the grid is also flown without the lever
   arm, beside it; and the innovations' white log-likelihood with GNSS present (every sensor, the configured
   noise; :func:`modelgen.navigator.likelihood.log_likelihood`) at no lever arm and at the chosen one, stated
   (added after the first run, as information, not a decision: with each chosen component alone too);
4. then (for 15 states; issue 26 item 5) stage 7 again with the lever arm and the rate limit in the configuration
   (``--fixed-point CONFIG --both-starts``, the selector as written) and its point shipped if it moves the numbers
   (bench/results/navigator_tuning_stage10_fixed_point_15*, navigator_tuning_stage10_selector.*).

Stage 8 (``--select [STAGE7_JSON ...] [--json FILE]``): step 5's selection on stage 7's committed fixed points
(default: bench/results/navigator_tuning_stage7_both_starts_{15,15_white,21,21_white}.json), without running the
iteration again: one GNSS-present flight per point.

The Python navigator flies these flights: it is the one that records every update's innovation and its
covariance (the generated C navigator does not hand them out).  Each flight's statistics are kept, so the
stage-4 measurement of an iteration is the last stage-5 flight of the one before, at no extra flight.

No outage is flown and no outage error is computed here: the choice cannot
see them.  Prints a table and the chosen values, which go into
modelgen/data/replay_drive_0708.yaml by hand (with this script named there).

    python bench/navigator_tuning.py            # stages 1-3 (about 5 minutes)
    python bench/navigator_tuning.py --stage3   # stage 3 only (seconds)
    python bench/navigator_tuning.py --correlation [CONFIG] [--json FILE]   # stage 4 (about a minute)
    python bench/navigator_tuning.py --likelihood [CONFIG] [--json FILE]    # stage 5 (about half an hour)
    python bench/navigator_tuning.py --markov [CONFIG] [--json FILE]        # stage 6 (about half an hour)
    python bench/navigator_tuning.py --markov-check [STAGE6_JSON] [--json FILE]   # stage 6b (a few minutes)
    python bench/navigator_tuning.py --fixed-point [CONFIG] [--both-starts] [--json FILE]   # stage 7 (both: about a quarter of an hour)
    python bench/navigator_tuning.py --select [STAGE7_JSON ...] [--json FILE]   # stage 8 (a few minutes)
    python bench/navigator_tuning.py --lever-arm [CONFIG ...] [--json FILE]   # stage 10 (a few minutes)
"""

from __future__ import annotations

import dataclasses
import math
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from scipy.stats import chi2

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

FACTORS = (3.0, 5.0, 7.0, 10.0)
#: the values stages 1-3 left the keys stage 4 sets at (the GNSS variance factors were 1: not there before)
STAGE4_FROM = {"gnss_position_variance_factor": 1.0, "gnss_velocity_variance_factor": 1.0,
               "nhc_sigma_lateral": 0.03, "nhc_sigma_vertical": 0.03, "zupt_sigma": 0.02}
NHC_SIGMAS = (0.03, 0.05, 0.1)
#: the white-noise factor stage 1 chose (the filter stages 4 and 5 measure from)
STAGE1_WHITE_FACTOR = 7.0
#: stage 7: the relative change of every stage-4 number and of the white-noise factor below which the iteration
#: has converged, and the most iterations (a stage 4 and a stage 5 each)
FIXED_POINT_TOLERANCE = 0.02
FIXED_POINT_ITERATIONS = 8
#: stage 7's bounded search: half-width of the interval in log10 of the white-noise factor, and its tolerance
FIXED_POINT_HALF_WIDTH = 0.25
FIXED_POINT_XATOL = 0.004
#: stage 10: the NHC sigma of the fit's flight [m/s] (its updates move nothing), the Newey-West window [s], the
#: significance and the largest plausible lever arm component [m], the rate-limit grid [deg/s; 1e9: none] and the
#: relative margin on the median GNSS NIS within which the largest limit is taken
LEVER_PROBE_SIGMA = 1000.0
LEVER_NEWEY_WEST_S = 5.0
LEVER_SIGNIFICANCE = 3.0
LEVER_PLAUSIBLE_M = 5.0
RATE_LIMITS_DEG_S = (1e9, 20.0, 10.0, 5.0)
RATE_LIMIT_NIS_MARGIN = 0.02


def _flight(args: tuple[float, float, float, str]) -> tuple[float, float, float, float, float]:
    """Median GNSS NIS and median NHC NIS of one flight without outages or gate."""
    from modelgen.navigator import errorstate
    from modelgen.navigator.spec import navigator_spec
    from modelgen.navigator.config import builtin_config_path, load_config
    from modelgen.navigator.logs import read_imu_csv, read_rtklib_pos
    from modelgen.navigator.navigator import fly, prepare

    gyro, accel, nhc, model_file = args
    config = load_config(builtin_config_path())
    noise = dict(config.noise)
    for kind, factor in (("gyro_white", gyro), ("accel_white", accel)):
        entry = noise[kind]
        noise[kind] = dataclasses.replace(entry, factor=factor, si=entry.si / entry.factor * factor)
    config = dataclasses.replace(config, noise=noise, outage_schedule=None, outage_windows=None,
                                 nis_gate_probability=1.0, nhc_sigma_lateral=nhc, nhc_sigma_vertical=nhc)
    nhc_nis: list[float] = []
    original = errorstate.ErrorStateFilter.update

    def recording(self, z, H, r, gate):
        result = original(self, z, H, r, gate)
        if len(z) == 2:
            nhc_nis.append(result.nis)
        return result

    errorstate.ErrorStateFilter.update = recording
    inputs = prepare(config, read_imu_csv(config.imu_file, config.imu_columns), read_rtklib_pos(config.gnss_file))
    flight = fly(config, inputs, navigator_spec(Path(model_file)))
    return gyro, accel, nhc, float(np.median(flight.gnss_nis)), float(np.median(nhc_nis)) if nhc_nis else math.nan


def main() -> None:
    """Run the grid (two processes), print the table and the choice."""

    from modelgen.navigator.config import builtin_config_path, load_config
    from modelgen.navigator.errorstate import model_path

    base = load_config(builtin_config_path())
    path = str(model_path(base.model, base.path))  # each worker derives it once (navigator_spec)
    target6, target2 = chi2.ppf(0.5, 6), chi2.ppf(0.5, 2)
    nhc0 = base.nhc_sigma_lateral
    with ProcessPoolExecutor(2) as pool:
        rows = list(pool.map(_flight, [(k, k, nhc0, path) for k in FACTORS]))
    print(f"stage 1: median GNSS NIS (target {target6:.2f}), NHC sigma {nhc0} m/s")
    print("factor  median NIS")
    for g, _, _, nis, _ in rows:
        print(f"{g:6g}  {nis:10.2f}")
    g, a, _, nis, _ = min(rows, key=lambda row: abs(math.log(row[3] / target6)))
    print(f"chosen: gyro_white factor {g:g}, accel_white factor {a:g} (median NIS {nis:.2f})")
    with ProcessPoolExecutor(2) as pool:
        rows2 = list(pool.map(_flight, [(g, a, s, path) for s in NHC_SIGMAS]))
    print(f"stage 2: median NHC NIS (target {target2:.2f})")
    for _, _, s, nis6, nis2 in rows2:
        print(f"NHC sigma {s:5.2f} m/s: median NHC NIS {nis2:7.2f}, median GNSS NIS {nis6:6.2f}")
    best = min(rows2, key=lambda row: abs(math.log(row[4] / target2)))
    print(f"chosen: NHC sigma {best[2]:g} m/s")
    stage3()


def stage3() -> None:
    """NHC angular-rate limit and gate probability from GNSS-present flights of the C navigator."""
    from modelgen.navigator.cnav import cached_c_navigator, fly_c
    from modelgen.navigator.config import DEG, builtin_config_path, load_config
    from modelgen.navigator.errorstate import model_path
    from modelgen.navigator.logs import read_imu_csv, read_rtklib_pos
    from modelgen.navigator.metrics import errors_against_reference, summary
    from modelgen.navigator.navigator import prepare

    base = load_config(builtin_config_path())
    inputs = prepare(base, read_imu_csv(base.imu_file, base.imu_columns), read_rtklib_pos(base.gnss_file))
    from modelgen.navigator.spec import navigator_spec

    navigator, _ = cached_c_navigator(navigator_spec(model_path(base.model, base.path), with_python=False))
    print("stage 3: GNSS everywhere, C navigator")
    print("gate probability    NHC rate limit  median NIS  RMS vs receiver [m]  de-weighted epochs")
    for probability in (0.9999, 1 - 1e-6, 1 - 1e-9, 1.0):
        for rate in (1e9, 20.0, 10.0, 5.0):
            config = dataclasses.replace(base, outage_schedule=None, outage_windows=None,
                                         nis_gate_probability=probability, nhc_rate_max=rate * DEG)
            flight, _ = fly_c(config, inputs, navigator)
            s = summary(flight, errors_against_reference(flight, inputs.gnss), inputs.gnss)
            print(f"{probability:<18.12g}  {'none' if rate > 1e8 else f'{rate:g} deg/s':>14}  "
                  f"{s['gnss_nis_median']:10.2f}  {s['horizontal_rms_outside_outages_m']:19.3f}  "
                  f"{s['counts']['gnss_deweighted']:18d}")


def _json_option(arguments: list[str]) -> tuple[str | None, list[str]]:
    """(FILE of ``--json FILE`` or None, the other arguments)."""
    if "--json" not in arguments:
        return None, arguments
    i = arguments.index("--json")
    return arguments[i + 1], arguments[:i] + arguments[i + 2:]


def _stage_start(arguments: list[str]):
    """(shipped configuration, the configuration stages 4 and 5 measure from, inputs, spec).

    Stages 4 and 5 measure from the filter of stages 1-3: the keys stage 4 sets at their values before it, the
    white-noise factor at stage 1's; stage 5 then takes the stage-4 values from the shipped configuration.
    """
    from modelgen.navigator import likelihood as ml
    from modelgen.navigator.config import builtin_config_path, load_config
    from modelgen.navigator.errorstate import model_path
    from modelgen.navigator.logs import read_gnss, read_imu
    from modelgen.navigator.navigator import prepare
    from modelgen.navigator.spec import navigator_spec

    shipped = load_config(arguments[0] if arguments else builtin_config_path())
    config = ml.with_parameters(dataclasses.replace(shipped, **STAGE4_FROM),
                                {"noise.gyro_white.factor": STAGE1_WHITE_FACTOR})
    inputs = prepare(config, read_imu(config.imu_source, config.gap_factor, config.gap_action),
                     read_gnss(config.gnss_source))
    return shipped, config, inputs, navigator_spec(model_path(config.model, config.path))


def correlation(arguments: list[str]) -> None:
    """Stage 4: correlation factors from the innovations with GNSS present, the tuned numbers, NIS after."""
    import json

    from modelgen.navigator import tuning
    out_json, arguments = _json_option(arguments)
    shipped, config, inputs, spec = _stage_start(arguments)
    result = tuning.correlation_tuning(config, inputs, spec)
    print(tuning.format_result(result))
    for t in result["tuned"]:
        held = getattr(shipped, tuning.CONFIG_FIELDS[t["key"]])
        same = math.isclose(held, t["after"], rel_tol=0.01)
        print(f"  {shipped.path}: {t['key']} = {held:.4g} ({'the value above' if same else 'NOT the value above'})")
    if out_json:
        # the configuration named as the package names it, so the committed result does not hold this machine's path
        result = {**result, "configuration": Path(str(result["configuration"])).name}
        Path(out_json).write_text(json.dumps(result, indent=2) + "\n")
        print(f"written {out_json}")


def likelihood(arguments: list[str]) -> None:
    """Stage 5: the white-noise factor at the maximum of the innovations' likelihood with GNSS present."""
    import json
    import time

    from modelgen.navigator import likelihood as ml
    from modelgen.navigator import tuning
    out_json, arguments = _json_option(arguments)
    keys = ml.PROCESS_NOISE
    if "--all" in arguments:  # every parameter (see modelgen.navigator.likelihood: not what stage 5 sets)
        arguments.remove("--all")
        keys = ml.PARAMETERS
    if "--three" in arguments:  # the white-noise factor and both bias driving noises
        arguments.remove("--three")
        keys = ml.PARAMETERS[:3]
    shipped, stage4_from, inputs, spec = _stage_start(arguments)
    config = ml.with_parameters(stage4_from, {key: ml.parameter_value(shipped, key)
                                              for key in ml.PARAMETERS if key not in ml.PROCESS_NOISE})
    started = time.time()

    def progress(flights: int, total: float, values: dict[str, float]) -> None:
        print(f"  flight {flights:3d} ({time.time() - started:6.0f} s): log L {total:10.1f}  "
              + " ".join(f"{k.split('.')[-2] if k.startswith('noise.') else k}={v:.4g}" for k, v in values.items()),
              flush=True)

    print(f"stage 5: {config.path} ({spec.name}), GNSS present everywhere, no outage flown: maximum likelihood of "
          "the innovations over " + ", ".join(keys))
    estimate = ml.maximum_likelihood(config, ml.gnss_present_innovations(inputs, spec), keys, progress=progress)
    print(f"{estimate.flights} flights, converged: {estimate.converged} ({estimate.message})")
    print(f"log L {estimate.log_likelihood_before['total']:.1f} -> {estimate.log_likelihood_after['total']:.1f}")
    for key in keys:
        print(f"  {key}: {estimate.before[key]:.4g} -> {estimate.after[key]:.4g}")
    sources, _ = tuning.record_innovations(ml.with_parameters(config, estimate.after), inputs, spec)
    nis = [dataclasses.asdict(c) for c in tuning.consistency(sources)]
    print("NIS at the estimate (chi-square: mean = rows, 95 % inside):")
    for c in nis:
        print(f"  {c['source']:8} rows {c['rows']}  updates {c['updates']:5d}  mean {c['mean']:7.2f}  "
              f"median {c['median']:6.2f}  inside 95 % {100 * c['inside_95']:5.1f} %")
    if out_json:
        result = {"configuration": Path(str(config.path)).name, "model": spec.name, **dataclasses.asdict(estimate),
                  "nis_after": nis}
        Path(out_json).write_text(json.dumps(result, indent=2) + "\n")
        print(f"written {out_json}")


def markov(arguments: list[str]) -> None:
    """Stage 6: the shaping filter's tau and sigma_e (and the white-noise factor) by maximum likelihood, the
    decision against the 21-state configuration by AIC and BIC (module docstring)."""
    import json
    import time

    from modelgen.navigator import likelihood as ml
    from modelgen.navigator import tuning
    from modelgen.navigator.config import load_config
    from modelgen.navigator.errorstate import model_path
    from modelgen.navigator.logs import read_gnss, read_imu
    from modelgen.navigator.navigator import prepare
    from modelgen.navigator.spec import navigator_spec
    from modelgen.fileio.datafiles import package_path

    out_json, arguments = _json_option(arguments)
    shipped = load_config(arguments[0] if arguments else package_path("data", "replay_drive_0708_gm.yaml"))
    baseline = load_config(package_path("data", "replay_drive_0708_21.yaml"))
    inputs = prepare(shipped, read_imu(shipped.imu_source, shipped.gap_factor, shipped.gap_action),
                     read_gnss(shipped.gnss_source))
    spec21 = navigator_spec(model_path(baseline.model, baseline.path))
    spec = navigator_spec(model_path(shipped.model, shipped.path))
    started = time.time()
    # 1. the start: the 21-state filter with the position R white
    white21 = dataclasses.replace(baseline, gnss_position_variance_factor=1.0)
    sources, _ = tuning.record_innovations(white21, inputs, spec21)
    start = tuning.markov_start(sources, spec21)
    print(f"stage 6: {shipped.path} ({spec.name}), GNSS present everywhere, no outage flown")
    print(f"1. autocovariance of the position innovations, 21 states, R white (T = {start['period_s']:.3f} s):")
    for label, fit in start["rows"].items():
        print(f"   {label:15} tau {fit.tau_s:5.2f} s  sigma_e {fit.sigma:.4f} m  (lags 1..{fit.lags}, rest "
              f"{fit.white_sigma:.4f} m)")
    pooled = start["pooled"]
    print(f"   mean of the three: tau {pooled.tau_s:.2f} s, sigma_e {pooled.sigma:.4f} m")
    # the 21-state configuration at its own estimates
    base_sources, _ = tuning.record_innovations(baseline, inputs, spec21)
    base_l = ml.log_likelihood(base_sources)
    n_updates = sum(len(e.time) for e in base_sources.values())
    # 2. the estimate
    keys = ("noise.gyro_white.factor", "parameters.gnss_error_time", "parameters.gnss_error_sigma")
    config = ml.with_parameters(shipped, {"parameters.gnss_error_time": pooled.tau_s,
                                          "parameters.gnss_error_sigma": pooled.sigma,
                                          "noise.gyro_white.factor": ml.parameter_value(baseline,
                                                                                        "noise.gyro_white.factor")})

    def progress(flights: int, total: float, values: dict[str, float]) -> None:
        print(f"  flight {flights:3d} ({time.time() - started:6.0f} s): log L {total:10.1f}  "
              + " ".join(f"{k.split('.')[-2] if k.startswith('noise.') else k.split('.')[-1]}={v:.4g}"
                         for k, v in values.items()), flush=True)

    print("2. maximum likelihood over " + ", ".join(keys))
    estimate = ml.maximum_likelihood(config, ml.gnss_present_innovations(inputs, spec), keys, max_flights=90,
                                     progress=progress)
    print(f"{estimate.flights} flights, converged: {estimate.converged} ({estimate.message})")
    for key in keys:
        print(f"  {key}: {estimate.before[key]:.4g} -> {estimate.after[key]:.4g}")
    after = ml.with_parameters(config, estimate.after)
    sources, _ = tuning.record_innovations(after, inputs, spec)
    gm_l = ml.log_likelihood(sources)
    criteria = {"ins_gnss21_rw_nav (R x f)": ml.information_criteria(base_l["total"], 2, n_updates),
                "ins_gnss24_gm_nav (Gauss-Markov)": ml.information_criteria(gm_l["total"], 3, n_updates)}
    print("3. decision (log L with GNSS present; AIC, BIC):")
    for name, c in criteria.items():
        print(f"   {name:34} log L {c['log_likelihood']:10.1f}  k {c['parameters']}  AIC {c['aic']:10.1f}  "
              f"BIC {c['bic']:10.1f}")
    a, b = criteria.values()
    better = b["aic"] < a["aic"] and b["bic"] < a["bic"]
    print(f"   per sensor, 21 states: " + ", ".join(f"{k} {v:.1f}" for k, v in base_l.items()))
    print(f"   per sensor, 24 states: " + ", ".join(f"{k} {v:.1f}" for k, v in gm_l.items()))
    print(f"   -> {'the Gauss-Markov model is better: it is adopted' if better else 'the Gauss-Markov model is NOT better'}")
    stats = tuning.row_statistics(sources, tuning.row_labels(spec))
    print("4. whiteness of the innovations at the estimate (stage 4's statistics):")
    for st in stats:
        print(f"   {st.source:5} {st.label:15} tau {st.tau_s:6.2f} s  f {st.factor:6.2f}")
    nis = [dataclasses.asdict(c) for c in tuning.consistency(sources)]
    for c in nis:
        print(f"   NIS {c['source']:8} rows {c['rows']}  updates {c['updates']:5d}  mean {c['mean']:7.2f}  "
              f"median {c['median']:6.2f}  inside 95 % {100 * c['inside_95']:5.1f} %")
    if out_json:
        result = {"configuration": Path(str(shipped.path)).name, "model": spec.name,
                  "start": {"period_s": start["period_s"], "rows": {k: dataclasses.asdict(v) for k, v in start["rows"].items()},
                            "pooled": dataclasses.asdict(pooled)},
                  "estimate": dataclasses.asdict(estimate), "log_likelihood_21": base_l, "log_likelihood_24": gm_l,
                  "criteria": criteria, "adopted": better, "whiteness": [dataclasses.asdict(st) for st in stats],
                  "nis_after": nis}
        Path(out_json).write_text(json.dumps(result, indent=2, default=float) + "\n")
        print(f"written {out_json}")


def markov_check(arguments: list[str]) -> None:
    """Stage 6b (module docstring): the decision against the 21-state model at its own maximum likelihood."""
    import json
    import time

    from modelgen.navigator import likelihood as ml
    from modelgen.navigator import tuning
    from modelgen.navigator.config import load_config
    from modelgen.navigator.errorstate import model_path
    from modelgen.navigator.logs import read_gnss, read_imu
    from modelgen.navigator.navigator import prepare
    from modelgen.navigator.spec import navigator_spec
    from modelgen.fileio.datafiles import package_path

    out_json, arguments = _json_option(arguments)
    stage6 = json.loads(Path(arguments[0] if arguments else "bench/results/navigator_tuning_stage6_gm.json").read_text())
    baseline = load_config(package_path("data", "replay_drive_0708_21.yaml"))
    shipped = load_config(package_path("data", "replay_drive_0708_gm.yaml"))
    inputs = prepare(baseline, read_imu(baseline.imu_source, baseline.gap_factor, baseline.gap_action),
                     read_gnss(baseline.gnss_source))
    spec21 = navigator_spec(model_path(baseline.model, baseline.path))
    spec = navigator_spec(model_path(shipped.model, shipped.path))
    started = time.time()

    def progress(flights: int, total: float, values: dict[str, float]) -> None:
        print(f"  flight {flights:3d} ({time.time() - started:6.0f} s): log L {total:10.1f}  "
              + " ".join(f"{k}={v:.4g}" for k, v in values.items()), flush=True)

    white21 = dataclasses.replace(baseline, gnss_position_variance_factor=1.0)
    print("stage 6b: 21 states, position R white: maximum likelihood over the white-noise factor (GNSS present)")
    estimate21 = ml.maximum_likelihood(white21, ml.gnss_present_innovations(inputs, spec21),
                                       ("noise.gyro_white.factor",), progress=progress)
    l21w = estimate21.log_likelihood_after
    n_updates = stage6["criteria"]["ins_gnss21_rw_nav (R x f)"]["updates"]
    factor = stage6["estimate"]["after"]["noise.gyro_white.factor"]
    print(f"profile of log L over sigma_e at tau = 2 s, 24 states, white-noise factor {factor:.4g}:")
    profile = []
    for sigma in (0.001, 0.003, 0.01, 0.02, 0.05):
        config = ml.with_parameters(shipped, {"noise.gyro_white.factor": factor, "parameters.gnss_error_time": 2.0,
                                              "parameters.gnss_error_sigma": sigma})
        total = ml.log_likelihood(ml.gnss_present_innovations(inputs, spec)(config))["total"]
        profile.append({"tau_s": 2.0, "sigma_e_m": sigma, "log_likelihood": total})
        print(f"   sigma_e {sigma:6.3f} m: log L {total:10.1f}", flush=True)
    criteria = {"ins_gnss21_rw_nav (R x f)": stage6["criteria"]["ins_gnss21_rw_nav (R x f)"],
                "ins_gnss21_rw_nav (R white)": ml.information_criteria(l21w["total"], 1, n_updates),
                "ins_gnss24_gm_nav (Gauss-Markov)": stage6["criteria"]["ins_gnss24_gm_nav (Gauss-Markov)"]}
    print("decision (log L with GNSS present; AIC, BIC):")
    for name, c in criteria.items():
        print(f"   {name:34} log L {c['log_likelihood']:10.1f}  k {c['parameters']}  AIC {c['aic']:10.1f}  "
              f"BIC {c['bic']:10.1f}")
    gm = criteria["ins_gnss24_gm_nav (Gauss-Markov)"]
    better = all(gm["aic"] < c["aic"] and gm["bic"] < c["bic"] for name, c in criteria.items() if "24" not in name)
    print(f"   white-noise factor, 21 states R white: {estimate21.before['noise.gyro_white.factor']:.4g} -> "
          f"{estimate21.after['noise.gyro_white.factor']:.4g} ({estimate21.flights} flights)")
    print(f"   -> {'the Gauss-Markov model is better than both: adopted' if better else 'the Gauss-Markov model is NOT better than the 21-state model at its own estimate: not adopted'}")
    if out_json:
        result = {"estimate_21_white": dataclasses.asdict(estimate21), "profile": profile, "criteria": criteria,
                  "adopted": better}
        Path(out_json).write_text(json.dumps(result, indent=2, default=float) + "\n")
        print(f"written {out_json}")


def _fixed_point_one(config_file: str, start: str = "shipped") -> dict:
    """Stage 7 on one configuration (module docstring): the iterates, the fixed point and its statistics.

    ``start``: "shipped" (the configuration's numbers) or "white" (the stage-4 keys at their white values, the
    white-noise factor the configuration's).
    """
    import time

    from scipy.optimize import minimize_scalar

    from modelgen.navigator import likelihood as ml
    from modelgen.navigator import tuning
    from modelgen.navigator.config import load_config
    from modelgen.navigator.errorstate import model_path
    from modelgen.navigator.logs import read_gnss, read_imu
    from modelgen.navigator.navigator import prepare
    from modelgen.navigator.spec import navigator_spec

    shipped = load_config(config_file)
    name = Path(str(shipped.path)).name
    inputs = prepare(shipped, read_imu(shipped.imu_source, shipped.gap_factor, shipped.gap_action),
                     read_gnss(shipped.gnss_source))
    spec = navigator_spec(model_path(shipped.model, shipped.path))
    labels = tuning.row_labels(spec)
    white = dataclasses.replace(shipped, **STAGE4_FROM)  # the stage-4 keys at their white values
    keys = tuple(tuning.CONFIG_FIELDS)
    q_key = ml.PROCESS_NOISE[0]
    started = time.time()
    flights: dict[tuple, dict] = {}

    def say(message: str) -> None:
        print(f"[{name} {time.time() - started:6.0f} s] {message}", flush=True)

    def values_of(config) -> dict[str, float]:
        return {**{key: ml.parameter_value(config, key) for key in keys}, q_key: ml.parameter_value(config, q_key)}

    def fly(config) -> dict:
        """One flight with GNSS present: log L per sensor, NIS, row statistics (kept per configuration)."""
        point = tuple(round(v, 9) for v in values_of(config).values())
        if point not in flights:
            sources, _ = tuning.record_innovations(config, inputs, spec)
            flights[point] = {"log_likelihood": ml.log_likelihood(sources),
                              "nis": [dataclasses.asdict(c) for c in tuning.consistency(sources)],
                              "rows": tuning.row_statistics(sources, labels)}
            say(f"flight {len(flights):3d}: log L {flights[point]['log_likelihood']['total']:10.1f}  "
                f"{q_key.split('.')[1]} factor {values_of(config)[q_key]:.4g}")
        return flights[point]

    def relative(a: dict, b: dict) -> dict[str, float]:
        return {key: abs(a[key] / b[key] - 1.0) for key in a}

    current = shipped if start == "shipped" else white
    iterates = [{"iteration": 0, "values": values_of(current),
                 "note": "the shipped configuration" if start == "shipped" else "the stage-4 keys at their white values"}]
    converged = False
    say(f"stage 7: {spec.name}, GNSS present everywhere, no outage flown; start {iterates[0]['values']}")
    for iteration in range(1, FIXED_POINT_ITERATIONS + 1):
        # a. stage 4 on the current filter's own innovations: white value x f
        measured = fly(current)
        tuned = tuning.tune(white, measured["rows"], spec)
        stage4 = tuning.apply(current, tuned)
        # b. stage 5 given those numbers: 1-D bounded search over log10 of the white-noise factor
        q0 = ml.parameter_value(current, q_key)
        centre, searched = math.log10(q0), 0
        while True:
            lo, hi = centre - FIXED_POINT_HALF_WIDTH, centre + FIXED_POINT_HALF_WIDTH
            result = minimize_scalar(
                lambda x: -fly(ml.with_parameters(stage4, {q_key: 10.0 ** x}))["log_likelihood"]["total"],
                bounds=(lo, hi), method="bounded", options={"xatol": FIXED_POINT_XATOL})
            searched += int(result.nfev)
            at_bound = min(result.x - lo, hi - result.x) < 2 * FIXED_POINT_XATOL
            if not at_bound or searched > 60:
                break
            centre = float(result.x)
            say(f"  the maximum is at a bound of the interval (factor {10 ** result.x:.4g}): searched again around it")
        q = 10.0 ** float(result.x)
        current = ml.with_parameters(stage4, {q_key: q})
        values = values_of(current)
        change = relative(values, iterates[-1]["values"])
        iterates.append({"iteration": iteration, "values": values, "change": change,
                         "correlation_factors": {t.key: t.factor for t in tuned},
                         "measured_at": iterates[-1]["values"], "search_evaluations": searched,
                         "log_likelihood": -float(result.fun)})
        say(f"iteration {iteration}: " + ", ".join(
            f"{k.split('.')[-1] if 'noise' not in k else 'white'} {v:.4g} (moved {100 * change[k]:.1f} %)"
            for k, v in values.items()))
        if max(change.values()) < FIXED_POINT_TOLERANCE:
            converged = True
            break
    at = fly(current)  # the last stage-5 flight: the fixed point's statistics
    residual = tuning.tune(white, at["rows"], spec)
    say(f"{'converged' if converged else 'NOT converged'} after {len(iterates) - 1} iterations, {len(flights)} flights")
    return {"configuration": name, "model": spec.name, "start": start, "tolerance": FIXED_POINT_TOLERANCE,
            "max_iterations": FIXED_POINT_ITERATIONS, "white_values": dict(STAGE4_FROM), "converged": converged,
            "iterations": len(iterates) - 1, "flights": len(flights), "iterates": iterates,
            "fixed_point": values_of(current),
            "log_likelihood": at["log_likelihood"], "nis": at["nis"],
            "rows": [dataclasses.asdict(r) for r in at["rows"]],
            "correlation_factors": {t.key: t.factor for t in residual},
            "stage4_at_fixed_point": {t.key: t.after for t in residual},
            "log_likelihood_shipped": fly(shipped)["log_likelihood"], "nis_shipped": fly(shipped)["nis"],
            "states": spec.n_states,
            "seconds": time.time() - started}


def fixed_point(arguments: list[str]) -> None:
    """Stage 7: stages 4 and 5 alternated to a fixed point (module docstring); both configurations in two
    processes unless CONFIG is given."""
    import json

    from modelgen.fileio.datafiles import package_path

    out_json, arguments = _json_option(arguments)
    starts = ("shipped", "white") if "--both-starts" in arguments else ("shipped",)
    arguments = [a for a in arguments if a != "--both-starts"]
    files = arguments or [str(package_path("data", "replay_drive_0708.yaml")),
                          str(package_path("data", "replay_drive_0708_21.yaml"))]
    jobs = [(f, s) for f in files for s in starts]
    with ProcessPoolExecutor(min(2, len(jobs))) as pool:
        results = list(pool.map(_fixed_point_one, *zip(*jobs)))
    for r in results:
        print(f"stage 7 from the {r['start']} start: {r['configuration']} ({r['model']}): "
              f"{'converged' if r['converged'] else 'NOT converged'} "
              f"in {r['iterations']} iterations (tolerance {100 * r['tolerance']:g} %, cap {r['max_iterations']}), "
              f"{r['flights']} flights")
        for it in r["iterates"]:
            print(f"  {it['iteration']}: " + ", ".join(f"{k} {v:.4g}" for k, v in it["values"].items()))
        print("  the fixed point (shipped numbers) and the correlation factors its own innovations show:")
        for key, value in r["fixed_point"].items():
            f = r["correlation_factors"].get(key)
            print(f"    {key}: {value:.4g}" + (f"  (f there {f:.2f}: {r['stage4_at_fixed_point'][key]:.4g})"
                                              if f is not None else ""))
        print(f"  log L {r['log_likelihood']['total']:.1f} (" +
              ", ".join(f"{k} {v:.1f}" for k, v in r["log_likelihood"].items() if k != "total") + ")")
        for c in r["nis"]:
            print(f"  NIS {c['source']:8} rows {c['rows']}  updates {c['updates']:5d}  mean {c['mean']:7.2f}  "
                  f"median {c['median']:6.2f}  inside 95 % {100 * c['inside_95']:5.1f} %")
        print("  whiteness at the fixed point (stage 4's statistics):")
        for st in r["rows"]:
            print(f"    {st['source']:5} {st['label']:15} tau {st['tau_s']:6.2f} s  f {st['factor']:6.2f}")
    for f in files:  # step 5 of the method: of the fixed points found, the higher thinned composite log L ships
        found = [r for r in results if r["configuration"] == Path(f).name and r["converged"]]
        if len(found) > 1:
            print(_format_selection(_selection(f, found)))
    if out_json:
        for r in results:  # one file per run: FILE, or FILE_<states>[_white].json for several
            suffix = f"_{r['states']}" + ("_white" if r["start"] == "white" else "")
            path = Path(out_json) if len(results) == 1 else Path(out_json).with_name(
                f"{Path(out_json).stem}{suffix}.json")
            path.write_text(json.dumps(r, indent=2, default=float) + "\n")
            print(f"written {path}")


def _selection(config_file: str, points: list[dict]) -> dict:
    """Step 5 of stage 7 (module docstring): each fixed point (a stage-7 result) flown once with GNSS present, all
    scored by the thinned composite log-likelihood on the same epochs; the highest is the one shipped."""
    from modelgen.navigator import likelihood as ml
    from modelgen.navigator import tuning
    from modelgen.navigator.config import load_config
    from modelgen.navigator.errorstate import model_path
    from modelgen.navigator.logs import read_gnss, read_imu
    from modelgen.navigator.navigator import prepare
    from modelgen.navigator.spec import navigator_spec

    base = load_config(config_file)
    inputs = prepare(base, read_imu(base.imu_source, base.gap_factor, base.gap_action), read_gnss(base.gnss_source))
    spec = navigator_spec(model_path(base.model, base.path))
    labels = tuning.row_labels(spec)
    sources = {}
    for point in points:
        if point["start"] in sources:
            raise ValueError(f"two fixed points from the {point['start']} start")
        config = ml.with_parameters(base, point["fixed_point"])
        sources[point["start"]], _ = tuning.record_innovations(config, inputs, spec)
    score = ml.thinned_log_likelihood(sources)
    white = {name: ml.log_likelihood(s) for name, s in sources.items()}
    chosen = max(score.total, key=score.total.get)
    rows = [{**dataclasses.asdict(r), "label": labels.get(r.source, [])[r.row] if r.row < len(labels.get(r.source, []))
             else str(r.row)} for r in score.rows]
    return {"configuration": Path(config_file).name, "model": spec.name,
            "statistic": "thinned composite log-likelihood (modelgen.navigator.likelihood.thinned_log_likelihood)",
            "points": {p["start"]: p["fixed_point"] for p in points},
            "white_log_likelihood": white,
            "white_log_likelihood_stage7": {p["start"]: p["log_likelihood"] for p in points},
            "thinned": {"total": score.total, "by_source": score.by_source,
                        "first_offset_total": score.first_offset_total,
                        "difference_standard_error": score.difference_standard_error,
                        "left_out": list(score.left_out), "rows": rows},
            "chosen": chosen, "white_choice": max(white, key=lambda name: white[name]["total"])}


def _format_selection(result: dict) -> str:
    """Step 5's scores and decision as text."""
    thinned = result["thinned"]
    names = list(result["points"])
    lines = [f"selection for {result['configuration']} ({result['model']}): {result['statistic']}",
             f"  {'row':22} {'k':>4} {'epochs':>6}  " + "  ".join(f"{'f ' + n:>10} {'score ' + n:>14}" for n in names)]
    for r in thinned["rows"]:
        lines.append(f"  {r['source'] + ' ' + r['label']:22} {r['step']:4d} {r['epochs']:6d}  " + "  ".join(
            f"{r['factors'][n]:10.2f} {r['score'][n]:14.1f}" for n in names))
    for n in names:
        w = result["white_log_likelihood"][n]
        lines.append(f"  {n:8} thinned {thinned['total'][n]:10.1f} (" + ", ".join(
            f"{s} {v:.1f}" for s, v in thinned["by_source"][n].items())
            + f"; offset 0 {thinned['first_offset_total'][n]:.1f})"
            f"   white log L {w['total']:10.1f} (" + ", ".join(f"{s} {v:.1f}" for s, v in w.items() if s != "total") +
            f"; stage 7 stated {result['white_log_likelihood_stage7'][n]['total']:.1f})")
    for pair, se in thinned["difference_standard_error"].items():
        a, b = pair.split(" - ")
        d = thinned["total"][a] - thinned["total"][b]
        lines.append(f"  thinned {pair}: {d:.1f} (standard error of one thinned draw {se:.1f}; stated, not used)")
    if thinned["left_out"]:
        lines.append("  left out: " + ", ".join(thinned["left_out"]))
    lines.append(f"decision for {result['configuration']}: ship the fixed point from the {result['chosen']} start "
                 f"(the white log L would pick the {result['white_choice']} start)")
    return "\n".join(lines)


def select(arguments: list[str]) -> None:
    """Stage 8: step 5's selection on stage 7's committed fixed points (module docstring)."""
    import json

    from modelgen.fileio.datafiles import package_path

    out_json, arguments = _json_option(arguments)
    files = arguments or [f"bench/results/navigator_tuning_stage7_both_starts_{s}.json"
                          for s in ("15", "15_white", "21", "21_white")]
    runs = [json.loads(Path(f).read_text()) for f in files]
    results = []
    for name in dict.fromkeys(r["configuration"] for r in runs):
        found = [r for r in runs if r["configuration"] == name and r["converged"]]
        print(f"stage 8: {name}: {len(found)} converged fixed points ("
              + ", ".join(f"{r['start']} start" for r in found) + "), one GNSS-present flight each", flush=True)
        results.append(_selection(str(package_path("data", name)), found))
        print(_format_selection(results[-1]), flush=True)
    if out_json:
        Path(out_json).write_text(json.dumps({"selections": results}, indent=2, default=float) + "\n")
        print(f"written {out_json}")


def _lever_arm_data(config_file: str) -> dict:
    """Stage 10, step 1's data: the IMU's body lateral and vertical velocity, the bias-corrected body rate and the
    speed at every covariance step of a GNSS-present flight with the NHC on at no lever arm and a sigma so large it
    moves nothing (module docstring)."""
    from modelgen.navigator import tuning
    from modelgen.navigator.config import load_config
    from modelgen.navigator.errorstate import model_path
    from modelgen.navigator.logs import read_gnss, read_imu
    from modelgen.navigator.metrics import COLUMN
    from modelgen.navigator.navigator import prepare
    from modelgen.navigator.spec import navigator_spec

    shipped = load_config(config_file)
    inputs = prepare(shipped, read_imu(shipped.imu_source, shipped.gap_factor, shipped.gap_action),
                     read_gnss(shipped.gnss_source))
    spec = navigator_spec(model_path(shipped.model, shipped.path))
    probe = dataclasses.replace(shipped, nhc_enabled=True, nhc_lever_arm=(0.0, 0.0, 0.0), nhc_rate_max=1e9,
                                nhc_sigma_lateral=LEVER_PROBE_SIGMA, nhc_sigma_vertical=LEVER_PROBE_SIGMA)
    sources, flight = tuning.record_innovations(probe, inputs, spec)
    nhc = sources["nhc"]
    t = np.array(nhc.time)
    k = np.searchsorted(inputs.time, t)
    assert np.array_equal(inputs.time[k], t), "an NHC update off an IMU sample"
    out = flight.outputs

    def at(names: list[str]) -> np.ndarray:
        return np.column_stack([np.interp(t, out[:, COLUMN["time"]], out[:, COLUMN[n]]) for n in names])

    bias = at([f"gyro_bias_{a}" for a in "xyz"])
    scale = at([f"gyro_scale_factor_{a}" for a in "xyz"])
    speed = np.linalg.norm(at(["v_north", "v_east", "v_down"]), axis=1)
    period = tuning.update_period(t)
    return {"configuration": Path(str(shipped.path)).name, "model": spec.name, "time": t,
            "v_body": np.array(nhc.nu), "rate": (inputs.rate[k] - bias) / (1.0 + scale), "speed": speed,
            "period_s": period, "lags": int(round(LEVER_NEWEY_WEST_S / period)),
            "nis_median_gnss": float(np.median(flight.gnss_nis))}


def _fit_dict(result) -> dict:
    """A lever_fit.LeverArmFit as JSON."""
    return {**dataclasses.asdict(result), "significance": {k: result.significance(k) for k in result.estimate}}


def _format_fit(title: str, result) -> list[str]:
    from modelgen.navigator.lever_fit import UNITS, UNKNOWNS

    lines = [f"  {title}: {result.samples} steps, Newey-West over {result.lags} steps; RMS lateral "
             f"{result.raw_rms['lateral']:.4f} -> {result.residual_rms['lateral']:.4f} m/s, vertical "
             f"{result.raw_rms['vertical']:.4f} -> {result.residual_rms['vertical']:.4f} m/s"]
    for name, unit in zip(UNKNOWNS, UNITS):
        lines.append(f"    {name:19} {result.estimate[name]:+9.4f} {unit:4} +- {result.standard_error[name]:.4f} "
                     f"(OLS {result.ols_standard_error[name]:.4f}; {result.significance(name):6.1f} sigma)")
    return lines


def _rate_limit_grid(config, inputs, navigator) -> list[dict]:
    """Stage 3's flights (C navigator, GNSS everywhere) over the rate-limit grid at the configuration's lever arm."""
    from modelgen.navigator.cnav import fly_c
    from modelgen.navigator.config import DEG
    from modelgen.navigator.metrics import errors_against_reference, summary

    rows = []
    for rate in RATE_LIMITS_DEG_S:
        flown = dataclasses.replace(config, outage_schedule=None, outage_windows=None, nhc_rate_max=rate * DEG)
        flight, _ = fly_c(flown, inputs, navigator)
        s = summary(flight, errors_against_reference(flight, inputs.gnss), inputs.gnss)
        rows.append({"rate_max_deg_s": rate, "gnss_nis_median": s["gnss_nis_median"],
                     "horizontal_rms_vs_receiver_m": s["horizontal_rms_outside_outages_m"],
                     "gnss_deweighted": s["counts"]["gnss_deweighted"], "nhc_updates": s["counts"]["nhc_updates"]})
    return rows


def rate_limit_choice(rows: list[dict]) -> float:
    """Stage 10 step 3's rule: the largest limit whose median GNSS NIS is within the margin of the grid's lowest."""
    lowest = min(r["gnss_nis_median"] for r in rows)
    return max(r["rate_max_deg_s"] for r in rows if r["gnss_nis_median"] <= lowest * (1.0 + RATE_LIMIT_NIS_MARGIN))


def lever_arm(arguments: list[str]) -> None:
    """Stage 10 (module docstring): the NHC lever arm from GNSS-present data, then the rate limit again."""
    import json

    from modelgen.fileio.datafiles import package_path
    from modelgen.navigator import lever_fit
    from modelgen.navigator import likelihood as ml
    from modelgen.navigator import tuning
    from modelgen.navigator.cnav import cached_c_navigator
    from modelgen.navigator.config import load_config
    from modelgen.navigator.errorstate import model_path
    from modelgen.navigator.logs import read_gnss, read_imu
    from modelgen.navigator.navigator import prepare
    from modelgen.navigator.spec import navigator_spec

    out_json, arguments = _json_option(arguments)
    files = arguments or [str(package_path("data", "replay_drive_0708.yaml")),
                          str(package_path("data", "replay_drive_0708_21.yaml"))]
    with ProcessPoolExecutor(min(2, len(files))) as pool:
        data = list(pool.map(_lever_arm_data, files))
    results = []
    for f, d in zip(files, data):
        whole = lever_fit.fit(d["v_body"], d["rate"], d["speed"], d["lags"])
        middle = 0.5 * (d["time"][0] + d["time"][-1])
        halves = {}
        for name, part in (("first half", d["time"] < middle), ("second half", d["time"] >= middle)):
            halves[name] = lever_fit.fit(d["v_body"][part], d["rate"][part], d["speed"][part], d["lags"])
        chosen = tuple(round(v, 2) if whole.significance(k) > LEVER_SIGNIFICANCE and abs(v) <= LEVER_PLAUSIBLE_M
                       else 0.0 for k, v in zip(("l_x", "l_y", "l_z"), whole.lever_arm))
        print(f"stage 10: {d['configuration']} ({d['model']}), GNSS present everywhere, no outage flown; NHC at no "
              f"lever arm, sigma {LEVER_PROBE_SIGMA:g} m/s, no rate limit (median GNSS NIS {d['nis_median_gnss']:.2f})")
        print("\n".join(_format_fit("whole drive", whole)))
        for name, part in halves.items():
            print("\n".join(_format_fit(name, part)))
        print(f"  -> nhc.lever_arm_m {list(chosen)} (a component where it is above {LEVER_SIGNIFICANCE:g} sigma and "
              f"within {LEVER_PLAUSIBLE_M:g} m, else 0)")
        shipped = load_config(f)
        inputs = prepare(shipped, read_imu(shipped.imu_source, shipped.gap_factor, shipped.gap_action),
                         read_gnss(shipped.gnss_source))
        navigator, _ = cached_c_navigator(navigator_spec(model_path(shipped.model, shipped.path), with_python=False))
        arms = ((0.0, 0.0, 0.0), chosen)
        grids = {str(list(arm)): _rate_limit_grid(dataclasses.replace(shipped, nhc_lever_arm=arm), inputs, navigator)
                 for arm in arms}
        spec = navigator_spec(model_path(shipped.model, shipped.path))
        alone = tuple(tuple(v if i == j else 0.0 for j, v in enumerate(chosen)) for i in range(3) if chosen[i])
        likelihoods = {str(list(arm)): ml.log_likelihood(tuning.record_innovations(
            dataclasses.replace(shipped, nhc_lever_arm=arm), inputs, spec)[0])
            for arm in dict.fromkeys(arms + (alone if len(alone) > 1 else ()))}
        print("  innovations' log L with GNSS present (configured noise and rate limit): " + "; ".join(
            f"{arm} {v['total']:.1f} (" + ", ".join(f"{k} {x:.1f}" for k, x in v.items() if k != "total") + ")"
            for arm, v in likelihoods.items()), flush=True)
        print("  rate limit, C navigator, GNSS everywhere (stage 3's flights):")
        print("  lever arm             rate limit  median NIS  RMS vs receiver [m]  de-weighted  NHC updates")
        for arm, rows in grids.items():
            for r in rows:
                limit = "none" if r["rate_max_deg_s"] > 1e8 else f"{r['rate_max_deg_s']:g} deg/s"
                print(f"  {arm:20}  {limit:>10}  {r['gnss_nis_median']:10.3f}  {r['horizontal_rms_vs_receiver_m']:19.4f}"
                      f"  {r['gnss_deweighted']:11d}  {r['nhc_updates']:11d}")
            print(f"  {arm}: the rule picks {rate_limit_choice(rows):g} deg/s")
        results.append({"configuration": d["configuration"], "model": d["model"], "period_s": d["period_s"],
                         "probe_sigma_m_s": LEVER_PROBE_SIGMA, "fit": _fit_dict(whole),
                         "halves": {k: _fit_dict(v) for k, v in halves.items()}, "chosen_lever_arm_m": list(chosen),
                         "rate_limit_grid": grids, "log_likelihood": likelihoods,
                         "rate_limit_choice": {arm: rate_limit_choice(rows) for arm, rows in grids.items()}})
    if out_json:
        Path(out_json).write_text(json.dumps({"stage": 10, "results": results}, indent=2, default=float) + "\n")
        print(f"written {out_json}")


if __name__ == "__main__":
    if sys.argv[1:] == ["--stage3"]:
        stage3()
    elif sys.argv[1:2] == ["--correlation"]:
        correlation(sys.argv[2:])
    elif sys.argv[1:2] == ["--likelihood"]:
        likelihood(sys.argv[2:])
    elif sys.argv[1:2] == ["--markov"]:
        markov(sys.argv[2:])
    elif sys.argv[1:2] == ["--markov-check"]:
        markov_check(sys.argv[2:])
    elif sys.argv[1:2] == ["--fixed-point"]:
        fixed_point(sys.argv[2:])
    elif sys.argv[1:2] == ["--select"]:
        select(sys.argv[2:])
    elif sys.argv[1:2] == ["--lever-arm"]:
        lever_arm(sys.argv[2:])
    else:
        main()
