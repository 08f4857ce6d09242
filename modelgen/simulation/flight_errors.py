"""Errors of a flight's navigation outputs against its truth, in metres, m/s and radians.

Every figure and the summary of ``modelgen simulate`` measure the corrected
(and the free) outputs this way: horizontal position in metres north and east
of the truth, horizontal velocity, attitude about north, east and down.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from modelgen.simulation import earth
from modelgen.simulation.rotation import navigation_frame_attitude_error
from modelgen.simulation.trajectory import Trajectory


ARCSEC = math.pi / 180 / 3600


NMILE = 1852.0


@dataclass
class NavigationErrors:
    """Errors of navigation outputs against truth: horizontal position [m], velocity [m/s], attitude [rad]."""

    times: np.ndarray
    position: np.ndarray  # (T, 2) north, east
    velocity: np.ndarray  # (T, 2) north, east
    attitude: np.ndarray  # (T, 3) about N, E, D


def navigation_errors(outputs: np.ndarray, trajectory: Trajectory, times: np.ndarray | None = None) -> NavigationErrors:
    """Errors of ``outputs`` (one row per truth record, or per record at ``times`` of a decimated run)."""
    truth = trajectory.truth
    if times is not None:
        truth = truth[np.rint(times / trajectory.record_period).astype(int)]
    lat = truth[:, 1]
    meridian, prime_vertical = np.vectorize(earth.radii_of_curvature)(lat)
    position = np.stack([(outputs[:, 0] - lat) * (meridian + truth[:, 3]),
                         (outputs[:, 1] - truth[:, 2]) * (prime_vertical + truth[:, 3]) * np.cos(lat)], axis=1)
    velocity = outputs[:, 3:5] - truth[:, 4:6]
    attitude = navigation_frame_attitude_error(outputs[:, 6:10], truth[:, 7:11])
    return NavigationErrors(truth[:, 0], position, velocity, attitude)
