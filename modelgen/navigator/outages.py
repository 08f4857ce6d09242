"""Simulated GNSS outages: a periodic schedule or an explicit list of windows."""

from __future__ import annotations

import numpy as np


def outage_windows(schedule: dict[str, float] | None, windows: list[tuple[float, float]] | None,
                   first_epoch: float, last_epoch: float) -> list[tuple[float, float]]:
    """Absolute (start, end) times [s] of the outages.

    A schedule starts ``first_after_s`` after the first GNSS epoch, repeats every
    ``period_s`` and keeps every outage of ``length_s`` that ends at least
    ``end_margin_s`` before the last epoch (the anchor's rule: 11 outages on the
    549 s drive).  Explicit windows are [start, length] relative to the first
    epoch and are kept as given.
    """
    if windows is not None:
        return [(first_epoch + start, first_epoch + start + length) for start, length in windows]
    if schedule is None:
        return []
    out = []
    start = first_epoch + schedule["first_after_s"]
    while start + schedule["length_s"] <= last_epoch - schedule["end_margin_s"] + 1e-9:
        out.append((start, start + schedule["length_s"]))
        start += schedule["period_s"]
    return out


def in_outage(times: np.ndarray, windows: list[tuple[float, float]]) -> np.ndarray:
    """Boolean mask of the times inside any outage window (start <= t < end)."""
    mask = np.zeros(len(times), dtype=bool)
    for start, end in windows:
        mask |= (times >= start) & (times < end)
    return mask
