"""Checks on a read log that do not depend on its format: IMU gaps, GNSS fixes, GNSS inside the IMU span.

IMU gaps (``imu.gap_factor``, ``imu.gap_action``)
  An interval longer than ``gap_factor`` times the median interval is a gap.
  ``gap_action: refuse`` (the default) refuses the log at the first gap, naming
  the sample after it (file:line for a CSV), the gap's time and length.
  ``gap_action: propagate`` hands the gaps to the navigator as ``ImuLog.gaps``
  and notes each one.  The contract with the navigator loop for a propagated
  gap: the navigation state is carried across the gap (no data: the
  mechanization holds the last sample's rates), the covariance is propagated
  over the gap's full length, and no GNSS epoch that falls inside a gap is
  applied (:func:`epochs_inside_gaps` finds them; ``navigator.prepare`` drops
  them with a note), so that GNSS epochs are never stacked on the first
  sample after the gap.

GNSS fixes
  A GNSS log whose epochs all lack a fix, or none of whose epochs has a
  quality the configuration uses, or none of whose epochs lies inside the IMU
  log's time span, cannot align a navigator; each is refused with its own
  message here, before the alignment could blame the vehicle for not moving.
"""

from __future__ import annotations

import numpy as np

from modelgen.errors import ModelError
from modelgen.navigator.logs.records import QUALITY_NAMES, GnssLog, ImuGap, ImuLog

GAP_ACTIONS = ("refuse", "propagate")
MAX_GAP_NOTES = 5


def find_gaps(time: np.ndarray, factor: float) -> list[ImuGap]:
    """Every interval longer than ``factor`` times the median interval, as (start, length)."""
    if len(time) < 3:
        return []
    dt = np.diff(time)
    limit = factor * float(np.median(dt))
    return [ImuGap(float(time[i]), float(dt[i])) for i in np.nonzero(dt > limit)[0]]


def apply_gap_policy(log: ImuLog, factor: float, action: str) -> ImuLog:
    """Find the gaps of ``log``; refuse at the first one, or list and note them (see the module docstring)."""
    if action not in GAP_ACTIONS:
        raise ModelError(f"{log.path}: IMU gap action {action!r} is not one of {', '.join(GAP_ACTIONS)}")
    log.gaps = find_gaps(log.time, factor)
    if not log.gaps:
        return log
    median = float(np.median(np.diff(log.time)))
    if action == "refuse":
        first = log.gaps[0]
        after = int(np.searchsorted(log.time, first.end))
        raise ModelError(f"{log.where(after)}: IMU gap of {first.length:.3f} s after t = {first.start:.3f} s "
                         f"(longer than imu.gap_factor {factor:g} x the median interval {median:.4f} s); "
                         f"{len(log.gaps)} gap(s) in the log. Set imu.gap_action: propagate to fly across gaps")
    for gap in log.gaps[:MAX_GAP_NOTES]:
        log.notes.append(f"{log.path}: IMU gap of {gap.length:.3f} s after t = {gap.start:.3f} s: propagated "
                         "across (imu.gap_action: propagate)")
    if len(log.gaps) > MAX_GAP_NOTES:
        log.notes.append(f"{log.path}: {len(log.gaps) - MAX_GAP_NOTES} more IMU gap(s) propagated across")
    return log


def epochs_inside_gaps(gnss_time: np.ndarray, gaps: list[ImuGap], time_offset: float) -> np.ndarray:
    """Per GNSS epoch: it falls strictly inside an IMU gap (gap times shifted by the IMU ``time_offset``)."""
    inside = np.zeros(len(gnss_time), dtype=bool)
    for gap in gaps:
        inside |= (gnss_time > gap.start + time_offset) & (gnss_time < gap.end + time_offset)
    return inside


def check_logs(imu: ImuLog, gnss: GnssLog, quality_factor: dict[int, float], time_offset: float) -> None:
    """Refuse a pair of logs that cannot fly together: other time scales, or GNSS that cannot align anything."""
    if imu.time_scale != gnss.time_scale:
        raise ModelError(f"{gnss.path}: GNSS times are {gnss.time_scale} but the IMU's ({imu.path}) are "
                         f"{imu.time_scale}: both logs must be on one time scale (time_base)")
    check_gnss_fixes(gnss, quality_factor, float(imu.time[0] + time_offset), float(imu.time[-1] + time_offset))


def check_gnss_fixes(gnss: GnssLog, quality_factor: dict[int, float], imu_start: float, imu_end: float) -> None:
    """Refuse a GNSS log that cannot align anything: no fix, no used quality, nothing inside the IMU span."""
    if len(gnss.time) == 0:
        raise ModelError(f"{gnss.path}: no GNSS fix at all (every epoch is without a position fix)"
                         + (f"; {gnss.notes[-1]}" if gnss.notes else ""))
    inside = (gnss.time >= imu_start) & (gnss.time <= imu_end)
    if not inside.any():
        raise ModelError(f"{gnss.path}: no GNSS epoch inside the IMU log's time span "
                         f"({imu_start:.3f} .. {imu_end:.3f} s; GNSS {gnss.time[0]:.3f} .. {gnss.time[-1]:.3f} s)")
    used = np.array([int(q) in quality_factor for q in gnss.quality[inside]])
    if not used.any():
        found = sorted({int(q) for q in gnss.quality[inside]})
        named = ", ".join(f"{q} ({QUALITY_NAMES.get(q, 'unknown')})" for q in found)
        raise ModelError(f"{gnss.path}: no GNSS epoch inside the IMU span has a quality the configuration uses "
                         f"(gnss.quality_factor: Q {', '.join(map(str, sorted(quality_factor)))}; "
                         f"the log has Q {named})")
