"""Errors of a flight against the RTK reference, per outage and outside the outages.

The error is measured at the antenna: the navigator's antenna position at each
output time against the RTK antenna position linearly interpolated to that
time (the receiver's solution, all epochs, including those hidden from the
filter during the outages).  The consistency of the filter at an outage end is the normalized squared
horizontal error ``e^T P_h^-1 e`` of the horizontal error e = (north, east)
with the filter's own 2x2 horizontal position covariance P_h (sigma_N^2,
sigma_E^2 and their cross covariance): for a consistent filter it follows the
chi-square distribution with 2 degrees of freedom (mean 2), and an end is
inside the 95 % region when it is at most chi2.ppf(0.95, 2) = 5.99.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from modelgen.navigator.logs import GnssLog
from modelgen.navigator.mechanization import radii
from modelgen.navigator.navigator import OUTPUT_FIELDS, Flight

COLUMN = {name: i for i, name in enumerate(OUTPUT_FIELDS)}
DRIFT_TIMES = (5.0, 10.0, 15.0)
#: probability of the consistency region at the outage ends, and its bound for 2 degrees of freedom
CONSISTENCY_PROBABILITY = 0.95
NEES_BOUND_95 = float(chi2.ppf(CONSISTENCY_PROBABILITY, 2))


@dataclass
class Errors:
    """Per output epoch: north, east, up error [m], the horizontal sigma [m] and the 2x2 horizontal covariance."""

    time: np.ndarray
    north: np.ndarray
    east: np.ndarray
    up: np.ndarray
    sigma_horizontal: np.ndarray
    #: (epochs, 2, 2) horizontal position covariance [m^2], north-east order
    covariance_horizontal: np.ndarray | None = None

    def nees_horizontal(self, index: int) -> float:
        """e^T P_h^-1 e at one output epoch (2 degrees of freedom); NaN if P_h is not positive definite."""
        return normalized_squared_error(np.array([self.north[index], self.east[index]]),
                                        self.covariance_horizontal[index])

    @property
    def horizontal(self) -> np.ndarray:
        """Horizontal error [m]."""
        return np.hypot(self.north, self.east)

    @property
    def three_d(self) -> np.ndarray:
        """3-D error [m]."""
        return np.sqrt(self.north**2 + self.east**2 + self.up**2)


def errors_against_reference(flight: Flight, reference: GnssLog) -> Errors:
    """Antenna errors of every output epoch against the interpolated RTK positions."""
    o = flight.outputs
    t = o[:, COLUMN["time"]]
    lat = np.interp(t, reference.time, reference.latitude)
    lon = np.interp(t, reference.time, reference.longitude)
    h = np.interp(t, reference.time, reference.height)
    rm, rn = radii(float(lat[0]))
    north = (o[:, COLUMN["latitude"]] - lat) * (rm + h)
    east = (o[:, COLUMN["longitude"]] - lon) * (rn + h) * np.cos(lat)
    up = o[:, COLUMN["height"]] - h
    sn, se = o[:, COLUMN["sigma_north"]], o[:, COLUMN["sigma_east"]]
    covariance = np.empty((len(t), 2, 2))
    covariance[:, 0, 0], covariance[:, 1, 1] = sn**2, se**2
    covariance[:, 0, 1] = covariance[:, 1, 0] = o[:, COLUMN["cov_north_east"]]
    return Errors(t, north, east, up, np.hypot(sn, se), covariance)


def normalized_squared_error(error: np.ndarray, covariance: np.ndarray) -> float:
    """e^T P^-1 e (NaN when P is not positive definite)."""
    try:
        factor = np.linalg.cholesky(covariance)
    except np.linalg.LinAlgError:
        return float("nan")
    y = np.linalg.solve(factor, error)
    return float(y @ y)


def consistency(nees: list[float] | np.ndarray) -> dict[str, float | int | None]:
    """Mean normalized squared error and the fraction inside the 95 % region (2 degrees of freedom)."""
    values = np.array([v for v in nees if v is not None and math.isfinite(v)], dtype=float)
    return {"count": int(len(values)),
            "nees_mean": float(values.mean()) if len(values) else None,
            "nees_median": float(np.median(values)) if len(values) else None,
            "inside_95_fraction": float(np.mean(values <= NEES_BOUND_95)) if len(values) else None,
            "expected_nees_mean": 2.0, "bound_95": NEES_BOUND_95}


def path_length(reference: GnssLog, start: float, end: float) -> float:
    """Distance travelled along the RTK track between two times [m]."""
    inside = (reference.time >= start) & (reference.time <= end)
    times = np.concatenate([[start], reference.time[inside], [end]])
    lat = np.interp(times, reference.time, reference.latitude)
    lon = np.interp(times, reference.time, reference.longitude)
    rm, rn = radii(float(lat[0]))
    return float(np.sum(np.hypot(np.diff(lat) * rm, np.diff(lon) * rn * math.cos(float(lat[0])))))


def outage_records(flight: Flight, errors: Errors, reference: GnssLog) -> list[dict[str, float]]:
    """One record per outage: start, duration, distance, errors at the end and maximum, sigma, drifts."""
    records = []
    horizontal, three_d = errors.horizontal, errors.three_d
    for start, end in flight.outages:
        inside = np.nonzero((errors.time >= start) & (errors.time < end))[0]
        if len(inside) == 0:
            continue
        last = int(inside[-1])
        record = {
            "start_s": round(start - flight.first_epoch, 3),
            "duration_s": round(end - start, 3),
            "distance_m": path_length(reference, start, end),
            "horizontal_error_end_m": float(horizontal[last]),
            "error_3d_end_m": float(three_d[last]),
            "horizontal_error_max_m": float(horizontal[inside].max()),
            "sigma_horizontal_end_m": float(errors.sigma_horizontal[last]),
        }
        nees = errors.nees_horizontal(last)
        record["nees_horizontal_end"] = nees if math.isfinite(nees) else None
        record["inside_95"] = bool(math.isfinite(nees) and nees <= NEES_BOUND_95)
        for after in DRIFT_TIMES:
            upto = inside[errors.time[inside] <= start + after + 1e-6]
            record[f"drift_{int(after)}s_m"] = float(horizontal[upto[-1]]) if len(upto) else None
        records.append(record)
    return records


def summary(flight: Flight, errors: Errors, reference: GnssLog) -> dict[str, object]:
    """The numbers of the report: per-outage records, RMS outside outages, statistics, biases."""
    records = outage_records(flight, errors, reference)
    o = flight.outputs
    outside = o[:, COLUMN["in_outage"]] == 0
    horizontal = errors.horizontal
    ends = np.array([r["horizontal_error_end_m"] for r in records])
    nis = np.array([v for v in flight.gnss_nis if math.isfinite(v)])
    final = o[-1]
    return {
        "outages": records,
        "outage_count": len(records),
        "horizontal_error_end_rms_m": float(np.sqrt(np.mean(ends**2))) if len(ends) else None,
        "horizontal_error_end_median_m": float(np.median(ends)) if len(ends) else None,
        "horizontal_error_end_max_m": float(ends.max()) if len(ends) else None,
        "consistency": consistency([r["nees_horizontal_end"] for r in records]),
        "horizontal_rms_outside_outages_m": float(np.sqrt(np.mean(horizontal[outside] ** 2))),
        "epochs": int(len(o)),
        "epochs_outside_outages": int(outside.sum()),
        "gnss_nis_mean": float(nis.mean()) if len(nis) else None,
        "gnss_nis_median": float(np.median(nis)) if len(nis) else None,
        "gnss_nis_gate": flight.gate,
        "counts": dict(flight.counts),
        "final_gyro_bias_deg_s": [float(math.degrees(v)) for v in final[COLUMN["gyro_bias_x"]:COLUMN["gyro_bias_z"] + 1]],
        "final_accel_bias_mg": [float(v / 9.80665 * 1e3) for v in final[COLUMN["accel_bias_x"]:COLUMN["accel_bias_z"] + 1]],
        # the scale factors only where the model estimates them (a 15-state model holds them at 0)
        **{f"final_{kind}_ppm": [float(v * 1e6) for v in final[COLUMN[f"{kind}_x"]:COLUMN[f"{kind}_z"] + 1]]
           for kind in ("gyro_scale_factor", "accel_scale_factor") if kind in flight.estimated},
        "alignment_time_s": round(flight.alignment_time - flight.first_epoch, 3),
        "alignment": ({"roll_deg": math.degrees(flight.alignment["roll"]),
                       "pitch_deg": math.degrees(flight.alignment["pitch"]),
                       "heading_deg": math.degrees(flight.alignment["heading"]),
                       "rest_end_s": round(flight.alignment["rest_end"] - flight.first_epoch, 3),
                       "rest_samples": int(flight.alignment["rest_samples"])} if flight.alignment else None),
        "notes": list(flight.notes),
    }


def velocity_latency(gnss: GnssLog, candidates: np.ndarray | None = None) -> float:
    """The delay [s] of the GNSS velocity against its own position differences (least RMS mismatch).

    Uses the .pos file alone: the velocity over each interval from the position
    difference, placed at the interval's midpoint, against the reported velocity
    interpolated at the midpoint plus a trial delay.
    """
    if candidates is None:
        candidates = np.arange(-0.25, 0.2501, 0.0125)
    if gnss.velocity is None or len(gnss.time) < 3:
        return float("nan")
    rm, rn = radii(float(gnss.latitude[0]))
    north = (gnss.latitude - gnss.latitude[0]) * rm
    east = (gnss.longitude - gnss.longitude[0]) * rn * math.cos(float(gnss.latitude[0]))
    mid = 0.5 * (gnss.time[1:] + gnss.time[:-1])
    vn, ve = np.diff(north) / np.diff(gnss.time), np.diff(east) / np.diff(gnss.time)
    cost = [np.mean((np.interp(mid + d, gnss.time, gnss.velocity[:, 0]) - vn) ** 2
                    + (np.interp(mid + d, gnss.time, gnss.velocity[:, 1]) - ve) ** 2) for d in candidates]
    return float(candidates[int(np.argmin(cost))])


def schedule_record(name: str, flight: Flight, errors: Errors, reference: GnssLog,
                    target_end_rms_m: float | None = None) -> dict[str, object]:
    """One outage schedule flown: its end-of-outage errors, RMS and consistency (:func:`consistency`)."""
    records = outage_records(flight, errors, reference)
    ends = np.array([r["horizontal_error_end_m"] for r in records])
    return {"name": name, "outage_count": len(records),
            "outage_length_s": sorted({r["duration_s"] for r in records}),
            "horizontal_error_end_rms_m": float(np.sqrt(np.mean(ends**2))) if len(ends) else None,
            "target_end_rms_m": target_end_rms_m,
            "consistency": consistency([r["nees_horizontal_end"] for r in records]),
            "ends": [{k: r[k] for k in ("start_s", "duration_s", "horizontal_error_end_m", "sigma_horizontal_end_m",
                                        "nees_horizontal_end", "inside_95")} for r in records]}


def pooled_consistency(schedules: list[dict]) -> dict[str, float | int | None]:
    """:func:`consistency` over the outage ends of every schedule flown."""
    return consistency([end["nees_horizontal_end"] for s in schedules for end in s["ends"]])
