"""Errors of a flight against the RTK reference, per outage and outside the outages.

The error is measured at the antenna: the navigator's antenna position at each
output time against the RTK antenna position linearly interpolated to that
time (the receiver's solution, all epochs, including those hidden from the
filter during the outages).  The horizontal bound is the filter's own
sigma_h = sqrt(sigma_N^2 + sigma_E^2); an outage end is "inside 3 sigma" when
its horizontal error is at most 3 sigma_h.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from modelgen.navigator.logs import GnssLog
from modelgen.navigator.mechanization import radii
from modelgen.navigator.navigator import OUTPUT_FIELDS, Flight

COLUMN = {name: i for i, name in enumerate(OUTPUT_FIELDS)}
DRIFT_TIMES = (5.0, 10.0, 15.0)


@dataclass
class Errors:
    """Per output epoch: north, east, up error [m] and the horizontal sigma [m]."""

    time: np.ndarray
    north: np.ndarray
    east: np.ndarray
    up: np.ndarray
    sigma_horizontal: np.ndarray

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
    sigma = np.hypot(o[:, COLUMN["sigma_north"]], o[:, COLUMN["sigma_east"]])
    return Errors(t, north, east, up, sigma)


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
        record["inside_3sigma"] = bool(record["horizontal_error_end_m"] <= 3.0 * record["sigma_horizontal_end_m"])
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
        "outage_ends_inside_3sigma_fraction": (float(np.mean([r["inside_3sigma"] for r in records]))
                                               if records else None),
        "horizontal_rms_outside_outages_m": float(np.sqrt(np.mean(horizontal[outside] ** 2))),
        "epochs": int(len(o)),
        "epochs_outside_outages": int(outside.sum()),
        "gnss_nis_mean": float(nis.mean()) if len(nis) else None,
        "gnss_nis_median": float(np.median(nis)) if len(nis) else None,
        "gnss_nis_gate": flight.gate,
        "counts": dict(flight.counts),
        "final_gyro_bias_deg_s": [float(math.degrees(v)) for v in final[COLUMN["gyro_bias_x"]:COLUMN["gyro_bias_z"] + 1]],
        "final_accel_bias_mg": [float(v / 9.80665 * 1e3) for v in final[COLUMN["accel_bias_x"]:COLUMN["accel_bias_z"] + 1]],
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
