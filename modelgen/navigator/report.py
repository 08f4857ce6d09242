"""A flight's files: RTKLIB .pos and CSV trajectories, summary.md/json, SVG figures.

Everything is rendered in memory first and written as one folder by
:func:`modelgen.fileio.output.write_atomically` (staging folder + rename), so a failed
or interrupted replay never leaves a half-written report.  Figures are SVG
(text) so that they go through the same writer.
"""

from __future__ import annotations

import io
import json
import math
import time
from pathlib import Path

import numpy as np

from modelgen.navigator.config import NavigatorConfig
from modelgen.navigator.logs import GnssLog
from modelgen.navigator.mechanization import radii
from modelgen.navigator.metrics import COLUMN, NEES_BOUND_95, Errors
from modelgen.navigator.navigator import OUTPUT_FIELDS, Flight

DEAD_RECKONING_Q = 6  # RTKLIB's solution quality code for dead reckoning


def _gpst(t: float) -> str:
    """'YYYY/MM/DD hh:mm:ss.sss' of seconds since 1970 on the GPST calendar scale."""
    whole = math.floor(t)
    millis = int(round((t - whole) * 1000.0))
    if millis == 1000:
        whole, millis = whole + 1, 0
    return time.strftime("%Y/%m/%d %H:%M:%S", time.gmtime(whole)) + f".{millis:03d}"


#: Optional output fields the .pos writer uses when the flight carries them (else the column is 0, said in the header):
#: north-east, east-up, up-north position covariance [m^2] (RTKLIB writes them as signed square roots).
CROSS_COVARIANCE_FIELDS = ("cov_north_east", "cov_east_up", "cov_up_north")


def _signed_root(value: float) -> float:
    """RTKLIB's sdne/sdeu/sdun: sign(c) * sqrt(|c|) of a covariance c."""
    return math.copysign(math.sqrt(abs(value)), value)


FORWARD_SOLUTION = "forward real-time GNSS/INS, antenna position"
SMOOTHED_SOLUTION = "RTS-smoothed GNSS/INS (post-processed: uses GNSS before and after each epoch), antenna position"


def pos_text(flight: Flight, config: NavigatorConfig, solution: str = FORWARD_SOLUTION) -> str:
    """The trajectory (antenna) in RTKLIB's lat/lon/height .pos format with velocities.

    Times in GPST to the millisecond; sdn, sde, sdu are the filter's 1-sigma
    position (OUTPUT_FIELDS sigma_north/east/up), sdne, sdeu, sdun its cross
    covariances as signed roots when the flight carries them
    (:data:`CROSS_COVARIANCE_FIELDS`), else 0 and the header says so.  The file
    reads back with :func:`modelgen.navigator.logs.read_rtklib_pos`.
    """
    c = COLUMN
    cross = all(name in c for name in CROSS_COVARIANCE_FIELDS)
    lines = [f"% program   : modelgen replay ({config.name}, model {config.model})",
             f"% solution  : {solution}; Q 6 = dead reckoning (no GNSS update at the epoch)",
             "% sd        : sdn, sde, sdu = the solution's 1-sigma position; "
             + ("sdne, sdeu, sdun = its cross covariances (signed square roots)" if cross else
                "sdne, sdeu, sdun = 0 (the flight carries no cross covariance)"),
             "% (lat/lon/height=WGS84/ellipsoidal as in the input solution, Q=1:fix,2:float,5:single,6:dr)",
             "%  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)"
             "  sdne(m)  sdeu(m)  sdun(m) age(s)  ratio    vn(m/s)    ve(m/s)    vu(m/s)"]
    for row in flight.outputs:
        q = int(row[c["gnss_quality"]]) if row[c["gnss_used"]] else DEAD_RECKONING_Q
        roots = [_signed_root(row[c[name]]) for name in CROSS_COVARIANCE_FIELDS] if cross else [0.0, 0.0, 0.0]
        lines.append(f"{_gpst(row[c['time']])} {math.degrees(row[c['latitude']]):14.9f} "
                     f"{math.degrees(row[c['longitude']]):14.9f} {row[c['height']]:10.4f} {q:3d} {0:3d} "
                     f"{row[c['sigma_north']]:8.4f} {row[c['sigma_east']]:8.4f} {row[c['sigma_up']]:8.4f} "
                     f"{roots[0]:8.4f} {roots[1]:8.4f} {roots[2]:8.4f} {0.0:6.2f} {0.0:6.1f} "
                     f"{row[c['v_north']]:10.5f} {row[c['v_east']]:10.5f} {-row[c['v_down']]:10.5f}")
    return "\n".join(lines) + "\n"


def csv_text(flight: Flight, errors: Errors) -> str:
    """Every output field plus the errors against RTK, one row per output epoch, degrees for angles.

    Time to the millisecond (``%.3f`` s), latitude and longitude to 1e-9 deg
    (0.1 mm), every other value to 10 significant digits.
    """
    angles = {"latitude", "longitude", "roll", "pitch", "yaw"}
    header = [f"{n}_deg" if n in angles else n for n in OUTPUT_FIELDS]
    header += ["error_north_m", "error_east_m", "error_up_m", "error_horizontal_m", "sigma_horizontal_m"]
    formats = ["{:.3f}" if n == "time" else "{:.9f}" if n in ("latitude", "longitude") else "{:.10g}"
               for n in OUTPUT_FIELDS] + ["{:.10g}"] * 5
    rows = [",".join(header)]
    for i, row in enumerate(flight.outputs):
        values = [math.degrees(v) if n in angles else v for n, v in zip(OUTPUT_FIELDS, row)]
        values += [errors.north[i], errors.east[i], errors.up[i], errors.horizontal[i], errors.sigma_horizontal[i]]
        rows.append(",".join(f.format(v) for f, v in zip(formats, values)))
    return "\n".join(rows) + "\n"


def _svg(fig) -> str:
    """A matplotlib figure as SVG text without a date (reproducible)."""
    buffer = io.StringIO()
    fig.savefig(buffer, format="svg", metadata={"Date": None})
    import matplotlib.pyplot as plt

    plt.close(fig)
    return buffer.getvalue()


def figures(flight: Flight, errors: Errors, reference: GnssLog, schedules: list[dict] | None = None) -> dict[str, str]:
    """track.svg (local map, outages marked), error.svg (horizontal error and 2 sigma), biases.svg, and
    consistency.svg (:func:`consistency_figure`) when schedules are given."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rm, rn = radii(float(reference.latitude[0]))
    lat0, lon0 = reference.latitude[0], reference.longitude[0]

    def local(lat, lon):
        return (lon - lon0) * rn * math.cos(lat0), (lat - lat0) * rm

    o = flight.outputs
    t_rel = o[:, COLUMN["time"]] - flight.first_epoch
    out: dict[str, str] = {}
    fig, ax = plt.subplots(figsize=(7, 7))
    ex, ny = local(reference.latitude, reference.longitude)
    ax.plot(ex, ny, color="0.6", lw=2.5, label="RTK (reference)")
    nx, nyy = local(o[:, COLUMN["latitude"]], o[:, COLUMN["longitude"]])
    ax.plot(nx, nyy, color="C0", lw=0.8, label="navigator")
    for k, (start, end) in enumerate(flight.outages):
        inside = (o[:, COLUMN["time"]] >= start) & (o[:, COLUMN["time"]] < end)
        ax.plot(nx[inside], nyy[inside], color="C3", lw=1.5, label="navigator, GNSS outage" if k == 0 else None)
        if inside.any():
            ax.annotate(str(k + 1), (nx[inside][-1], nyy[inside][-1]), fontsize=8, color="C3")
    ax.set_aspect("equal")
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    ax.set_title("Track on a local map (outages in red, numbered at their end)")
    ax.legend(loc="best", fontsize=8)
    out["track.svg"] = _svg(fig)

    fig, ax = plt.subplots(figsize=(9, 4))
    ax.semilogy(t_rel, np.maximum(errors.horizontal, 1e-4), color="C0", lw=0.8, label="horizontal error")
    ax.semilogy(t_rel, np.maximum(errors.sigma_horizontal, 1e-4), color="C1", lw=0.8,
                label="filter sigma_h = sqrt(sigma_N^2 + sigma_E^2)")
    for start, end in flight.outages:
        ax.axvspan(start - flight.first_epoch, end - flight.first_epoch, color="C3", alpha=0.12)
    ax.set_xlabel("time since the first GNSS epoch [s]")
    ax.set_ylabel("[m]")
    ax.set_title("Horizontal error at the antenna against RTK (outages shaded)")
    ax.legend(fontsize=8)
    out["error.svg"] = _svg(fig)

    fig, (a1, a2) = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    for i, axis in enumerate("xyz"):
        a1.plot(t_rel, np.degrees(o[:, COLUMN[f"gyro_bias_{axis}"]]), lw=0.8, label=axis)
        a2.plot(t_rel, o[:, COLUMN[f"accel_bias_{axis}"]] / 9.80665 * 1e3, lw=0.8, label=axis)
    a1.set_ylabel("gyro bias [deg/s]")
    a2.set_ylabel("accelerometer bias [mg]")
    a2.set_xlabel("time since the first GNSS epoch [s]")
    a1.legend(fontsize=8)
    a1.set_title("Bias estimates (body axes)")
    out["biases.svg"] = _svg(fig)
    scales = [kind for kind in ("gyro_scale_factor", "accel_scale_factor") if kind in flight.estimated]
    if scales:  # the model estimates scale factors: their own figure
        fig, axes = plt.subplots(len(scales), 1, figsize=(9, 3 * len(scales)), sharex=True, squeeze=False)
        for ax, kind in zip(axes[:, 0], scales):
            for axis in "xyz":
                ax.plot(t_rel, o[:, COLUMN[f"{kind}_{axis}"]] * 1e6, lw=0.8, label=axis)
            ax.set_ylabel(f"{'gyro' if kind.startswith('gyro') else 'accelerometer'} scale factor [ppm]")
            ax.legend(fontsize=8)
        axes[-1, 0].set_xlabel("time since the first GNSS epoch [s]")
        axes[0, 0].set_title("Scale-factor estimates (body axes)")
        out["scale_factors.svg"] = _svg(fig)
    if schedules:
        out["consistency.svg"] = consistency_figure(schedules)
    return out


def consistency_figure(schedules: list[dict]) -> str:
    """consistency.svg: e^T P_h^-1 e at every outage end of every schedule, and their pooled distribution."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scipy.stats import chi2

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.2), gridspec_kw={"width_ratios": [3, 2]})
    markers = "osD^vP*X"
    pooled = []
    for i, schedule in enumerate(schedules):
        ends = [e for e in schedule["ends"] if e["nees_horizontal_end"] is not None]
        pooled += [e["nees_horizontal_end"] for e in ends]
        a1.semilogy([e["start_s"] + e["duration_s"] for e in ends], [max(e["nees_horizontal_end"], 1e-3) for e in ends],
                    markers[i % len(markers)], ms=4, color=f"C{i}", label=schedule["name"])
    a1.axhline(NEES_BOUND_95, color="k", ls="--", lw=0.8, label=f"95 % bound ({NEES_BOUND_95:.2f})")
    a1.axhline(2.0, color="k", ls=":", lw=0.8, label="expected mean (2)")
    a1.set_xlabel("end of the outage, time since the first GNSS epoch [s]")
    a1.set_ylabel("e^T P_h^-1 e at the outage end [dimensionless]")
    a1.set_title("Normalized squared horizontal error at each outage end")
    a1.legend(fontsize=7, loc="best")
    values = np.sort(np.array(pooled))
    if len(values):
        a2.semilogx(np.maximum(values, 1e-3), np.arange(1, len(values) + 1) / len(values), drawstyle="steps-post",
                    color="C0", label=f"outage ends, all schedules ({len(values)})")
        grid = np.logspace(-3, max(3.0, math.log10(max(values.max(), 1.0)) + 0.2), 200)
        a2.semilogx(grid, chi2.cdf(grid, 2), color="k", lw=0.8, label="chi-square, 2 degrees of freedom")
    a2.axvline(NEES_BOUND_95, color="k", ls="--", lw=0.8)
    a2.set_xlabel("e^T P_h^-1 e [dimensionless]")
    a2.set_ylabel("fraction of outage ends at or below")
    a2.set_title("Pooled distribution")
    a2.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    return _svg(fig)


def _fmt(value: object, digits: int = 2) -> str:
    """A number for the Markdown tables."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    return f"{value:.{digits}f}" if isinstance(value, float) else str(value)


def _table_cell(text: str) -> str:
    """A configuration's free text as one Markdown table cell: one line, its ``|`` escaped."""
    return " ".join(text.split()).replace("|", "\\|")


def _how_chosen(config: NavigatorConfig) -> str:
    """How this configuration's numbers were chosen, as far as the configuration itself says (its ``tuning:``).

    The built-in drive's stages are its own history (bench/navigator_tuning.py); a user's configuration
    went through none of them unless its ``tuning:`` says so, so the summary repeats only that record.
    """
    if not config.tuning:
        return ("How the values were chosen: the configuration states no tuning (no `tuning:` section), so every "
                "number above and below is as the configuration writes it (a noise = data sheet x its factor).")
    return ("How the values were chosen: as the configuration's `tuning:` section states, key by key, below; a number "
            "it does not list is as the configuration writes it. The tuning tool (bench/navigator_tuning.py in "
            "the repository; docs/replay-configuration.md) chooses them from the innovations of flights with "
            "GNSS everywhere, never from outage errors.")


def _tuning_lines(config: NavigatorConfig) -> list[str]:
    """The configuration's own statement of which numbers were tuned and how (its ``tuning:`` section)."""
    if not config.tuning:
        return []
    lines = ["Tuned numbers as the configuration states them (`tuning:`):", "", "| key | how |", "|---|---|"]
    lines += [f"| {_table_cell(key)} | {_table_cell(how)} |" for key, how in config.tuning.items()]
    return lines + [""]


def _alignment_lines(summary: dict) -> list[str]:
    """The alignment as the navigator that flew did it (the C aligns itself, by the Python reference's rules)."""
    a = summary.get("alignment")
    if not a:
        return []
    return ["## Alignment", "",
            f"By the {'Python' if summary.get('navigator') == 'python' else 'C'} navigator itself, from its IMU and GNSS calls: roll "
            f"{a['roll_deg']:.4f} deg and pitch {a['pitch_deg']:.4f} deg from the mean specific force of the "
            f"{a['rest_samples']} IMU samples that the IMU's still detector accepted in the rest window ending at the "
            "last GNSS epoch at rest "
            f"({a['rest_end_s']} s), which also give the gyro bias and the accelerometer bias along gravity; heading "
            f"{a['heading_deg']:.3f} deg from the GNSS course at {summary['alignment_time_s']} s, the first used epoch "
            "faster than the heading speed.", ""]


#: one line per figure of :func:`figures`, for the reports that show them
FIGURE_CAPTIONS = {
    "track.svg": "The drive on a local map: the navigator's track over the RTK reference, the GNSS outages in red, "
                 "numbered at their end.",
    "error.svg": "Horizontal error at the antenna against RTK [m] and the filter's horizontal sigma "
                 "sqrt(sigma_N^2 + sigma_E^2) [m] over the drive (log scale; the outages shaded).",
    "biases.svg": "The navigator's gyro (deg/s) and accelerometer (mg) bias estimates, body axes, over the drive.",
    "scale_factors.svg": "The navigator's gyro and accelerometer scale-factor estimates [ppm], body axes, over the "
                         "drive (drawn for a model with scale-factor states).",
    "consistency.svg": "Left: the normalized squared horizontal error e^T P_h^-1 e (e the north-east error at the "
                       "antenna against RTK, P_h the filter's 2x2 horizontal covariance; dimensionless) at the end of "
                       "every outage of every schedule flown, against the outage's end time, with the chi-square "
                       "(2 degrees of freedom) 95 % bound 5.99 and mean 2. Right: the pooled values' empirical "
                       "distribution against the chi-square distribution with 2 degrees of freedom.",
}


SMOOTHED_CAPTION = ("Horizontal error at the antenna against RTK [m] of the forward (real-time) and the RTS-smoothed "
                    "trajectory, with each one's filter sigma_h [m] dotted, over the drive (log scale; outages shaded).")


def targets(summary: dict, timings: dict[str, float]) -> list[dict]:
    """The replay's stated targets, each ``quantity``, ``reached``, ``target``, ``anchor`` (the published 15-state
    filter's value on the drive) and ``met`` (True, False, or None for a row that only informs).

    The end-of-outage RMS of each schedule and the pooled consistency are targets when the configuration states
    them (``evaluation``: the built-in drive's configuration states them); the rest are the navigator's own.
    """
    outside = summary["horizontal_rms_outside_outages_m"]
    difference = summary.get("c_python_max_difference_m")
    rows = []
    for schedule in summary.get("schedules", []):
        rms, target = schedule["horizontal_error_end_rms_m"], schedule["target_end_rms_m"]
        rows.append({"quantity": f"end-of-outage horizontal error, RMS, {schedule['name']} schedule "
                                 f"({schedule['outage_count']} outages)",
                     "reached": f"{_fmt(rms)} m", "target": f"<= {target:g} m" if target is not None else "",
                     "anchor": "7.44 m" if schedule["name"] == "configured" else "",
                     "met": (rms is not None and rms <= target) if target is not None else None})
    rows.append({"quantity": "end-of-outage horizontal error, median / max (configured schedule)",
                 "reached": f"{_fmt(summary['horizontal_error_end_median_m'])} / "
                            f"{_fmt(summary['horizontal_error_end_max_m'])} m",
                 "target": "", "anchor": "7.02 / 13.35 m", "met": None})
    pooled = summary.get("consistency_pooled") or summary.get("consistency") or {}
    goals = summary.get("evaluation_targets") or {}
    count = len(summary.get("schedules", [])) or 1
    mean, inside = pooled.get("nees_mean"), pooled.get("inside_95_fraction")
    nees_target = goals.get("target_nees_mean")
    rows.append({"quantity": f"mean normalized squared horizontal error e^T P_h^-1 e at the outage ends, pooled over "
                             f"{count} schedule(s) ({pooled.get('count', 0)} ends; 2 if consistent)",
                 "reached": _fmt(mean), "target": f"in [{nees_target[0]:g}, {nees_target[1]:g}]" if nees_target else "",
                 "anchor": "",
                 "met": (mean is not None and nees_target[0] <= mean <= nees_target[1]) if nees_target else None})
    inside_target = goals.get("target_inside_95_fraction")
    rows.append({"quantity": "outage ends inside the 95 % region (e^T P_h^-1 e <= 5.99), pooled",
                 "reached": f"{_fmt(100 * inside if inside is not None else None, 0)} %",
                 "target": f">= {100 * inside_target:g} %" if inside_target is not None else "", "anchor": "",
                 "met": (inside is not None and inside >= inside_target) if inside_target is not None else None})
    rows += [
        {"quantity": "horizontal RMS outside outages", "reached": f"{_fmt(outside, 3)} m", "target": "<= 0.10 m",
         "anchor": "0.057 m", "met": outside <= 0.10},
        {"quantity": "navigator CPU time, C, whole log", "reached": f"{_fmt(timings.get('fly_c_cpu_s'), 3)} s",
         "target": "<= 0.5 s (549 s drive)", "anchor": "",
         "met": timings["fly_c_cpu_s"] <= 0.5 if "fly_c_cpu_s" in timings else None},
        {"quantity": "navigator wall time, Python reference", "reached": f"{_fmt(timings.get('fly_python_s'), 2)} s",
         "target": "", "anchor": "11.9 s", "met": None},
        {"quantity": "C against Python, largest antenna-position difference",
         "reached": f"{difference:.2g} m" if difference is not None else "not flown (--navigator both)",
         "target": "<= 0.001 m", "anchor": "", "met": difference <= 1e-3 if difference is not None else None},
    ]
    return rows + smoothed_targets(summary.get("smoothed"))


def smoothed_targets(smoothed: dict | None) -> list[dict]:
    """The smoother's target rows (replay --smooth): RMS over every outage epoch and the largest outage maximum."""
    if not smoothed:
        return []
    rms, target_rms = smoothed["smoothed"]["horizontal_error_outage_rms_m"], smoothed["target_outage_rms_m"]
    maxima = [o["smoothed_horizontal_error_max_m"] for o in smoothed["outages"]]
    target_max = smoothed["target_outage_max_m"]
    over = smoothed.get("outages_over_max") or []
    return [{"quantity": "smoothed horizontal error, RMS over every outage epoch (configured schedule)",
             "reached": f"{_fmt(rms, 3)} m (forward {_fmt(smoothed['forward']['horizontal_error_outage_rms_m'], 3)} m)",
             "target": f"<= {target_rms:g} m" if target_rms is not None else "", "anchor": "",
             "met": smoothed["outage_rms_met"]},
            {"quantity": f"smoothed horizontal error, largest per-outage maximum ({len(maxima)} outages)",
             "reached": f"{_fmt(max(maxima) if maxima else None, 3)} m"
                        + (f" (outages over the target: {', '.join(map(str, over))})" if over else ""),
             "target": f"<= {target_max:g} m each" if target_max is not None else "", "anchor": "0.25-0.69 m",
             "met": smoothed["outage_max_met"]}]


def _smoothed_lines(summary: dict) -> list[str]:
    """The smoother's section: forward and smoothed errors per outage, and over all outage epochs."""
    sm = summary.get("smoothed")
    if not sm:
        return []
    f, s = sm["forward"], sm["smoothed"]
    lines = ["## Smoothed (replay --smooth)", "",
             "A fixed-interval Rauch-Tung-Striebel smoother run backward over the recorded forward pass of the "
             "reported navigator (the generated filter's transitions and covariances; the error-state resets of the "
             "closed loop referred back step by step with the model's reset Jacobian), by the model's generated "
             f"backward pass ({sm.get('backward_pass') or 'generated'}). "
             "Post-processing: each smoothed epoch uses GNSS from before and after it. The forward columns are that "
             "forward pass, errors measured the same way. Files: `smoothed.pos`, `smoothed.csv`, `smoothed.svg`.", "",
             "![smoothed](smoothed.svg)", "",
             "| # | start_s | duration_s | forward end_m | smoothed end_m | forward max_m | smoothed max_m | "
             "forward sigma_h end_m | smoothed sigma_h end_m |", "|---|---|---|---|---|---|---|---|---|"]
    for k, o in enumerate(sm["outages"], start=1):
        lines.append(f"| {k} | {_fmt(o['start_s'], 1)} | {_fmt(o['duration_s'], 1)} | "
                     f"{_fmt(o['forward_horizontal_error_end_m'], 3)} | {_fmt(o['smoothed_horizontal_error_end_m'], 3)} | "
                     f"{_fmt(o['forward_horizontal_error_max_m'], 3)} | {_fmt(o['smoothed_horizontal_error_max_m'], 3)} | "
                     f"{_fmt(o['forward_sigma_horizontal_end_m'], 3)} | {_fmt(o['smoothed_sigma_horizontal_end_m'], 3)} |")
    lines += ["", "| horizontal error [m] | forward | smoothed |", "|---|---|---|",
              f"| RMS at the outage ends | {_fmt(f['horizontal_error_end_rms_m'], 3)} | "
              f"{_fmt(s['horizontal_error_end_rms_m'], 3)} |",
              f"| RMS over every outage epoch | {_fmt(f['horizontal_error_outage_rms_m'], 3)} | "
              f"{_fmt(s['horizontal_error_outage_rms_m'], 3)} |",
              f"| largest in any outage | {_fmt(f['horizontal_error_outage_max_m'], 3)} | "
              f"{_fmt(s['horizontal_error_outage_max_m'], 3)} |",
              f"| RMS outside the outages | {_fmt(f['horizontal_rms_outside_outages_m'], 3)} | "
              f"{_fmt(s['horizontal_rms_outside_outages_m'], 3)} |",
              f"| mean e^T P_h^-1 e over every outage epoch (2 if consistent; dimensionless) | "
              f"{_fmt(f['nees_horizontal_outage_mean'], 1)} | {_fmt(s['nees_horizontal_outage_mean'], 1)} |", ""]
    for row in smoothed_targets(sm):
        verdict = "" if row["met"] is None else ("met" if row["met"] else "missed")
        lines.append(f"- {row['quantity']}: {row['reached']}" + (f", target {row['target']}: {verdict}"
                                                               if row["target"] else ""))
    return lines + [""]


def smoothed_figure(forward: Flight, smoothed: Flight, reference: GnssLog) -> str:
    """smoothed.svg: horizontal error against RTK of the forward and the smoothed trajectory over time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from modelgen.navigator.metrics import errors_against_reference

    fig, ax = plt.subplots(figsize=(9, 4))
    for flight, color, label in ((forward, "C0", "forward (real time)"), (smoothed, "C2", "RTS-smoothed")):
        e = errors_against_reference(flight, reference)
        ax.semilogy(e.time - flight.first_epoch, np.maximum(e.horizontal, 1e-4), color=color, lw=0.8,
                    label=f"{label}, horizontal error")
        ax.semilogy(e.time - flight.first_epoch, np.maximum(e.sigma_horizontal, 1e-4), color=color, lw=0.6, ls=":",
                    label=f"{label}, filter sigma_h")
    for start, end in forward.outages:
        ax.axvspan(start - forward.first_epoch, end - forward.first_epoch, color="C3", alpha=0.12)
    ax.set_xlabel("time since the first GNSS epoch [s]")
    ax.set_ylabel("horizontal error at the antenna [m]")
    ax.set_title("Forward and smoothed horizontal error against RTK (outages shaded)")
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.18), ncol=2)
    fig.tight_layout()
    return _svg(fig)


def _consistency_lines(summary: dict) -> list[str]:
    """The consistency section: every schedule's RMS and NEES statistics, and the pooled ones."""
    schedules = summary.get("schedules") or []
    if not schedules:
        return []
    lines = ["## Consistency over outage schedules", "",
             "Each schedule is the same log flown again with GNSS hidden in its outages (`outages` and "
             "`evaluation.schedules` of the configuration). NEES is the normalized squared horizontal error "
             "e^T P_h^-1 e at an outage end: e the north-east error at the antenna against RTK, P_h the filter's "
             "2x2 horizontal covariance (sigma_N^2, sigma_E^2 and their cross covariance). For a consistent filter "
             "it is chi-square with 2 degrees of freedom: mean 2, and 95 % of the ends at or below "
             f"{NEES_BOUND_95:.2f}. Nothing was tuned on these numbers.", "",
             "| schedule | outages | length_s | end RMS_m | target | mean NEES | median NEES | inside 95 % |",
             "|---|---|---|---|---|---|---|---|"]
    for s in schedules:
        c = s["consistency"]
        lengths = ", ".join(f"{v:g}" for v in s["outage_length_s"])
        lines.append(f"| {s['name']} | {s['outage_count']} | {lengths} | {_fmt(s['horizontal_error_end_rms_m'])} | "
                     f"{'<= %g' % s['target_end_rms_m'] if s['target_end_rms_m'] is not None else ''} | "
                     f"{_fmt(c['nees_mean'], 1)} | {_fmt(c['nees_median'], 1)} | "
                     f"{_fmt(100 * c['inside_95_fraction'] if c['inside_95_fraction'] is not None else None, 0)} % |")
    p = summary["consistency_pooled"]
    lines.append(f"| pooled | {p['count']} | | | | {_fmt(p['nees_mean'], 1)} | {_fmt(p['nees_median'], 1)} | "
                 f"{_fmt(100 * p['inside_95_fraction'] if p['inside_95_fraction'] is not None else None, 0)} % |")
    return lines + [""]


def _overconfidence_lines(summary: dict) -> list[str]:
    """What the pooled NEES of this flight's outage schedules says, computed from them (nothing stated for a
    configuration this report did not fly)."""
    p = summary.get("consistency_pooled") or {}
    if not summary.get("schedules") or p.get("nees_mean") is None:
        return []
    inside = p.get("inside_95_fraction")
    return ["When the mean NEES at the outage ends is far above 2 the filter is overconfident: its horizontal "
            "covariance does not contain errors its model lacks or underrates. Here, pooled over the "
            f"{p['count']} outage ends of every schedule: mean {_fmt(p['nees_mean'], 2)} against 2"
            + (f", {_fmt(100 * inside, 0)} % inside the 95 % region" if inside is not None else "") + ".", ""]


def summary_markdown(summary: dict, config: NavigatorConfig, timings: dict[str, float], latency: float) -> str:
    """summary.md: outage table, targets, tuning and how it was chosen, counts and notes."""
    lines = [f"# Replay: {config.name}", "",
             f"Configuration `{Path(config.path).name}`, model `{config.model}` (generated filter, closed loop), "
             f"{'generated C' if summary.get('navigator') == 'c' else 'Python reference'} navigator. "
             "Forward real-time filter: nothing after a moment is used at that moment. The error is measured at the "
             "antenna against the RTK solution interpolated to each output time (all RTK epochs, including those "
             "hidden during the outages).", "",
             "## Outages", "",
             "| # | start_s | duration_s | distance_m | horizontal_error_end_m | error_3d_end_m | horizontal_error_max_m "
             "| sigma_horizontal_end_m | NEES (2 dof) | inside 95 % | drift 5 s | drift 10 s | drift 15 s |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for k, r in enumerate(summary["outages"], start=1):
        lines.append(f"| {k} | {_fmt(r['start_s'], 1)} | {_fmt(r['duration_s'], 1)} | {_fmt(r['distance_m'], 1)} | "
                     f"{_fmt(r['horizontal_error_end_m'])} | {_fmt(r['error_3d_end_m'])} | "
                     f"{_fmt(r['horizontal_error_max_m'])} | {_fmt(r['sigma_horizontal_end_m'])} | "
                     f"{_fmt(r['nees_horizontal_end'], 1)} | {'yes' if r['inside_95'] else 'no'} | {_fmt(r['drift_5s_m'])} | {_fmt(r['drift_10s_m'])} | "
                     f"{_fmt(r['drift_15s_m'])} |")
    lines += [""] + _consistency_lines(summary) + _smoothed_lines(summary)
    lines += ["## Targets", "",
              "| quantity | reached | target | anchor (published 15-state filter) | |",
              "|---|---|---|---|---|"]
    for row in targets(summary, timings):
        verdict = "" if row["met"] is None else ("met" if row["met"] else "missed")
        lines.append("|" + "|".join(f" {cell} " if cell else " " for cell in
                                    (row["quantity"], row["reached"], row["target"], row["anchor"], verdict)) + "|")
    lines.append("")
    lines += ["## Tuning and how it was chosen", "",
              "IMU noise = data-sheet value x unit x stated factor (configuration `noise`):", "",
              "| noise | data sheet | factor | SI value used | why |", "|---|---|---|---|---|"]
    for kind, entry in config.noise.items():
        lines.append(f"| {kind} | {entry.value:g} {entry.unit} | {entry.factor:g} | {entry.si:.4g} | {entry.why} |")
    lines += ["",
              _how_chosen(config), "",
              *_tuning_lines(config),
              f"GNSS NIS in this flight (outside outages): mean {_fmt(summary['gnss_nis_mean'])}, median "
              f"{_fmt(summary['gnss_nis_median'])}; gate {_fmt(summary['gnss_nis_gate'])} (chi-square, 6 degrees of "
              f"freedom, probability {config.nis_gate_probability}); above it an update is "
              + ("de-weighted (R scaled by NIS / gate)." if config.gate_action == "deweight" else
                 f"rejected, and after {config.gate_release_epochs} rejected epochs in a row the next one is accepted."),
              "",
              f"GNSS velocity latency used {config.velocity_latency:.3f} s; estimated from the .pos file alone "
              f"(velocity against position differences): {latency:.3f} s.", "",
              f"GNSS sigmas: the receiver's, times {config.quality_factor} by quality Q, floors "
              f"{config.minimum_sigma_position} m and {config.minimum_sigma_velocity} m/s; variance factors "
              f"{config.gnss_position_variance_factor:g} (position) and {config.gnss_velocity_variance_factor:g} "
              "(velocity).", "",
              f"ZUPT {'on' if config.zupt_enabled else 'off'} (sigma {config.zupt_sigma} m/s), NHC "
              f"{'on' if config.nhc_enabled else 'off'} (sigma {config.nhc_sigma_lateral} / "
              f"{config.nhc_sigma_vertical} m/s above {config.nhc_speed_min} m/s, below "
              f"{math.degrees(config.nhc_rate_max):.3g} deg/s of angular rate).", "",
              *_overconfidence_lines(summary),
              "## Estimated biases (end of the drive, body axes)", "",
              f"gyro [deg/s]: {', '.join(f'{v:.4f}' for v in summary['final_gyro_bias_deg_s'])}; "
              f"accelerometer [mg]: {', '.join(f'{v:.2f}' for v in summary['final_accel_bias_mg'])}"
              + "".join(f"; {label} [ppm]: {', '.join(f'{v:.0f}' for v in summary[key])}"
                        for key, label in (("final_gyro_scale_factor_ppm", "gyro scale factor"),
                                           ("final_accel_scale_factor_ppm", "accelerometer scale factor"))
                        if key in summary) + ".", "",
              "## Counts", "",
              ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in summary["counts"].items())
              + f"; alignment at {summary['alignment_time_s']} s after the first GNSS epoch; "
              f"{summary['epochs']} output epochs.", "", *_alignment_lines(summary)]
    if "embedded" in summary:
        e = summary["embedded"]
        stack = ", ".join(f"`{k}` {v} B" for k, v in e["worst_case_stack_bytes"].items())
        lines += ["## Embedded (Cortex-M4F, single-precision filter)", "",
                  "The error-state filter is generated in single precision (the FPU's format); the mechanization keeps "
                  "position, velocity and attitude in double (a float latitude resolves 0.6 m), software floating point "
                  "on the M4F.", "",
                  f"- code: .text {e['cortex_m4f_text_bytes']} B, .data {e['cortex_m4f_data_bytes']} B, .bss "
                  f"{e['cortex_m4f_bss_bytes']} B (filter and navigator objects, -O2); the caller's navigator struct "
                  f"{e['navigator_struct_bytes']} B (of which {e['rest_max_samples'] * 7 * 8} B hold the last "
                  f"{e['rest_max_samples']} IMU samples for the navigator's own alignment, idle once aligned, and "
                  f"{e['window_max_samples'] * 2 * 8} B the zero-velocity detector's window of {e['window_max_samples']}); no heap ({'none' if not e['heap_or_stdio_symbols'] else ', '.join(e['heap_or_stdio_symbols'])} "
                  "of malloc/free/printf... referenced)",
                  f"- worst-case stack (call graph): {stack}",
                  f"- the whole log under qemu-arm against the double C navigator: largest antenna-position difference "
                  f"{e['qemu_max_position_difference_m']:.2g} m at any output epoch (stated tolerance {e['tolerance_m']} m: "
                  f"{'met' if e['qemu_max_position_difference_m'] <= e['tolerance_m'] else 'missed'})", ""]
    if summary["notes"]:
        lines += ["## Input notes", ""] + [f"- {n}" for n in summary["notes"]] + [""]
    lines += ["## Files", "",
              "`trajectory.pos` (RTKLIB format: opens in RTKLIB's rtkplot), `trajectory.csv`, `summary.json`, "
              + ", ".join(f"`{name}`" for name in FIGURE_CAPTIONS if _drawn(name, summary)) + ".", ""]
    lines += [line for name in FIGURE_CAPTIONS if _drawn(name, summary)
              for line in (f"![{name.removesuffix('.svg')}]({name})", "")]
    return "\n".join(lines)


def _drawn(figure: str, summary: dict) -> bool:
    """Whether :func:`figures` draws ``figure`` for this summary (the consistency figure needs the schedules, the
    scale-factor figure a model with scale-factor states)."""
    if figure == "consistency.svg":
        return bool(summary.get("schedules"))
    if figure == "scale_factors.svg":
        return any(key in summary for key in ("final_gyro_scale_factor_ppm", "final_accel_scale_factor_ppm"))
    return True


def report_files(flight: Flight, errors: Errors, summary: dict, config: NavigatorConfig, reference: GnssLog,
                 timings: dict[str, float], latency: float, with_figures: bool = True,
                 smoothed: tuple[Flight, Flight] | None = None) -> dict[str, str]:
    """Every file of report/replay/ as name -> text; ``smoothed`` (forward, smoothed flights) adds the smoother's."""
    record = dict(summary)
    record["timings_s"] = timings
    record["gnss_velocity_latency_estimated_s"] = latency
    record["noise"] = {k: {"value": e.value, "unit": e.unit, "factor": e.factor, "si": e.si, "why": e.why}
                       for k, e in config.noise.items()}
    record["targets"] = targets(summary, timings)
    record["figures"] = ({k: v for k, v in FIGURE_CAPTIONS.items() if _drawn(k, summary)} if with_figures else {})
    if with_figures and smoothed is not None:
        record["figures"]["smoothed.svg"] = SMOOTHED_CAPTION
    files = {"summary.md": summary_markdown(summary, config, timings, latency),
             "summary.json": json.dumps(record, indent=2, allow_nan=False, default=_json_default) + "\n",
             "trajectory.pos": pos_text(flight, config),
             "trajectory.csv": csv_text(flight, errors)}
    if with_figures:
        files.update(figures(flight, errors, reference, summary.get("schedules")))
    if smoothed is not None:
        from modelgen.navigator.metrics import errors_against_reference

        files["smoothed.pos"] = pos_text(smoothed[1], config, SMOOTHED_SOLUTION)
        files["smoothed.csv"] = csv_text(smoothed[1], errors_against_reference(smoothed[1], reference))
        if with_figures:
            files["smoothed.svg"] = smoothed_figure(smoothed[0], smoothed[1], reference)
    return files


def _json_default(value: object) -> object:
    """numpy scalars to plain numbers for json."""
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return value.item()
    raise TypeError(f"not JSON serializable: {type(value).__name__}")
