"""Flight paths to truth trajectories and ideal IMU increments on WGS-84.

A flight path (the ``start`` and ``segments`` of a flight profile) is a
start state and a list of segments; within a segment the
controls are constant: horizontal (along-track) acceleration, turn rate
(heading rate), vertical acceleration (rate of change of the down velocity,
which is how the core paper describes its climb and level-off, the core paper §3) and
roll rate.  Horizontal ground speed, heading, down velocity, roll and height
are then closed-form in time; latitude and longitude are integrated (RK4 on the
IMU grid).  The body x axis points along the velocity (pitch = flight-path
angle, no angle of attack or sideslip), so the attitude is
C_b^n = Rz(heading) Ry(flight-path angle) Rx(roll).

The ideal IMU outputs are what a perfect strapdown IMU delivers: the angle
increment  Delta theta_k = int omega_ib^b dt  and the velocity increment
Delta v_k = int f^b dt  over each sample interval, with
omega_ib^b = omega_nb^b + C_n^b (omega_ie^n + omega_en^n) and
f^b = C_n^b (dv^n/dt + (2 omega_ie^n + omega_en^n) x v^n - g^n).
Both integrals are evaluated by 3-point Gauss-Legendre quadrature, split at
segment boundaries, so they are exact to ~1e-15 relative for these smooth
integrands: the increments carry the coning and sculling of the true motion,
which the mechanization must then resolve.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from modelgen.errors import ModelError
from modelgen.simulation import earth
from modelgen.simulation.jit import compiled, inlined
from modelgen.simulation.rotation import euler_quaternion, half_angle_quaternion, rotate_vector

# Column layout of the recorded truth (one row per record time).
TRUTH_COLUMNS = (
    "time",
    "latitude",
    "longitude",
    "height",
    "velocity_north",
    "velocity_east",
    "velocity_down",
    "q0",
    "q1",
    "q2",
    "q3",
)
MINIMUM_SPEED = 1.0  # m/s; the flight-path angle is undefined for a hovering vehicle


@dataclass(frozen=True)
class Segment:
    """Constant controls over ``duration`` seconds (SI units, angles in rad)."""

    name: str
    duration: float
    horizontal_acceleration: float = 0.0  # d(ground speed)/dt [m/s^2]
    turn_rate: float = 0.0  # d(heading)/dt [rad/s]
    vertical_acceleration: float = 0.0  # d(V_down)/dt [m/s^2]
    roll_rate: float = 0.0  # d(roll)/dt [rad/s]


@dataclass(frozen=True)
class FlightPath:
    """Start state plus segments; see the module docstring for the kinematics."""

    name: str
    latitude: float  # rad
    longitude: float  # rad
    height: float  # m
    ground_speed: float  # horizontal speed, m/s
    heading: float  # rad, from north towards east
    velocity_down: float  # m/s (negative = climbing)
    roll: float  # rad
    segments: tuple[Segment, ...]

    @property
    def duration(self) -> float:
        return float(sum(s.duration for s in self.segments))

    def truncated(self, duration: float) -> "FlightPath":
        """The same flight flown for only the first ``duration`` seconds."""
        if duration <= 0:
            raise ModelError(f"profile {self.name!r}: duration must be positive, got {duration}")
        kept, left = [], duration
        for s in self.segments:
            if left <= 0:
                break
            kept.append(Segment(s.name, min(s.duration, left), s.horizontal_acceleration, s.turn_rate,
                                s.vertical_acceleration, s.roll_rate))
            left -= s.duration
        if left > 1e-9:  # longer than the profile: extend the last segment (its controls held)
            last = kept[-1]
            kept[-1] = Segment(last.name, last.duration + left, last.horizontal_acceleration, last.turn_rate,
                               last.vertical_acceleration, last.roll_rate)
        return FlightPath(self.name, self.latitude, self.longitude, self.height, self.ground_speed,
                             self.heading, self.velocity_down, self.roll, tuple(kept))


@dataclass(frozen=True)
class Trajectory:
    """Truth and ideal IMU increments of one flight.

    ``delta_theta[k]`` and ``delta_velocity[k]`` are the increments over
    ``[k dt, (k+1) dt]``; ``truth`` rows are taken every ``record_every``
    samples (row j at time ``j * record_every * dt``), columns :data:`TRUTH_COLUMNS`.
    A *streamed* trajectory (``generate_trajectory(..., streamed=True)``) holds
    the truth only (``delta_theta``/``delta_velocity`` are None): its increments
    are generated on demand, a piece at a time, by :meth:`increments`, bit for
    bit the rows a whole trajectory holds.  A streamed trajectory made with
    ``positions_in_pieces=True`` has the latitude and longitude of its truth
    rows filled by those pieces as they are made, in order (NaN until then,
    but for row 0): the position is integrated once, not once for the truth
    and again for the increments.
    """

    path: FlightPath
    imu_rate: float
    record_every: int
    delta_theta: np.ndarray | None
    delta_velocity: np.ndarray | None
    truth: np.ndarray
    sample_count: int = -1  # streamed: the number of IMU samples (the arrays give it otherwise)
    positions_in_pieces: bool = False  # streamed: truth latitude and longitude filled by the pieces, in order

    @property
    def dt(self) -> float:
        return 1.0 / self.imu_rate

    @property
    def streamed(self) -> bool:
        """True when the increments are generated on demand (:meth:`increments`), not held."""
        return self.delta_theta is None

    @property
    def n_samples(self) -> int:
        return self.sample_count if self.delta_theta is None else self.delta_theta.shape[0]

    @property
    def record_period(self) -> float:
        return self.record_every / self.imu_rate

    def initial_state(self) -> np.ndarray:
        """Truth at t = 0: latitude, longitude, height, v_NED (3), q_b^n (4)."""
        return self.truth[0, 1:].copy()

    def increments(self, start: int, stop: int) -> tuple[np.ndarray, np.ndarray]:
        """Ideal (delta_theta, delta_velocity) of samples [start, stop), each (stop - start, 3).

        A held trajectory returns slices of its arrays; a streamed one computes
        them now, starting from the truth row at ``start`` (which must be a
        record sample: a multiple of ``record_every``).  With
        :attr:`positions_in_pieces` that row's position must be known (the
        pieces before it made), and the piece fills the positions of the truth
        rows it reaches.
        """
        stop = min(stop, self.n_samples)
        if self.delta_theta is not None:
            return self.delta_theta[start:stop], self.delta_velocity[start:stop]
        if start % self.record_every:
            raise ModelError(f"trajectory: a streamed piece must start at a record sample, not {start}")
        row = start // self.record_every
        if self.positions_in_pieces and math.isnan(self.truth[row, 1]):
            raise ModelError(f"trajectory: the position at sample {start} is not known yet (the truth positions are "
                             "integrated by the pieces: make them in order)")
        delta_theta = np.empty((max(stop - start, 0), 3))
        delta_velocity = np.empty_like(delta_theta)
        _increments(segment_table(self.path), self.truth[row, 1], self.truth[row, 2], self.dt, start, stop,
                    delta_theta, delta_velocity, self.truth, self.record_every, self.positions_in_pieces)
        return delta_theta, delta_velocity


#: columns of :func:`segment_table` after the controls and start state: an angle held through a segment
#: (flag 1/0, then its cosine, sine and the cosine and sine of its half) -- heading, roll, pitch
HEADING_HELD, ROLL_HELD, PITCH_HELD = 10, 15, 20
SEGMENT_COLUMNS = 25


def segment_table(profile: FlightPath) -> np.ndarray:
    """Per segment: start time, controls and the closed-form state at its start, and the held angles.

    Columns: start, a_h, turn_rate, a_v, roll_rate, V_h0, heading0, V_d0, roll0, h0, then
    (:data:`HEADING_HELD`...) the trigonometry of each angle a segment holds constant (:func:`_held_angles`).
    """
    rows = []
    t, vh, psi, vd, roll, h = 0.0, profile.ground_speed, profile.heading, profile.velocity_down, profile.roll, profile.height
    for s in profile.segments:
        rows.append([t, s.horizontal_acceleration, s.turn_rate, s.vertical_acceleration, s.roll_rate, vh, psi, vd, roll, h])
        T = s.duration
        end_speed = vh + s.horizontal_acceleration * T
        if min(vh, end_speed) < MINIMUM_SPEED and math.hypot(min(vh, end_speed), vd) < MINIMUM_SPEED:
            raise ModelError(f"profile {profile.name!r}, segment {s.name!r}: speed falls below {MINIMUM_SPEED} m/s")
        if end_speed < 0 or vh < 0:
            raise ModelError(f"profile {profile.name!r}, segment {s.name!r}: ground speed becomes negative")
        h = h - vd * T - 0.5 * s.vertical_acceleration * T * T
        vh, psi, vd, roll = end_speed, psi + s.turn_rate * T, vd + s.vertical_acceleration * T, roll + s.roll_rate * T
        t += T
        if abs(roll) >= math.radians(89.0):
            raise ModelError(f"profile {profile.name!r}, segment {s.name!r}: roll reaches {math.degrees(roll):.1f} deg")
    table = np.zeros((len(rows), SEGMENT_COLUMNS))
    table[:, :10] = np.array(rows, dtype=float).reshape(len(rows), 10)
    _held_angles(table)
    return table


@compiled
def _held_angles(table):
    """Fill the held-angle columns: the cosines and sines every sample of a segment would compute again.

    A segment without turn rate holds its heading, without roll rate its roll,
    without horizontal and vertical acceleration its pitch (the flight-path
    angle).  The angle is formed as :func:`_kinematics` forms it (start value
    plus rate times elapsed time, the product a zero of the rate's sign for any
    time in the segment) and its functions computed here, by the same compiled
    calls, once: the increments and truth then read them, bit for bit the
    values they computed per sample (2-3x fewer sines and cosines in cruise).
    """
    for i in range(table.shape[0]):
        if table[i, 2] == 0.0:
            psi = table[i, 6] + table[i, 2] * 0.0
            table[i, HEADING_HELD] = 1.0
            table[i, HEADING_HELD + 1], table[i, HEADING_HELD + 2] = math.cos(psi), math.sin(psi)
            table[i, HEADING_HELD + 3], table[i, HEADING_HELD + 4] = math.cos(0.5 * psi), math.sin(0.5 * psi)
        if table[i, 4] == 0.0:
            roll = table[i, 8] + table[i, 4] * 0.0
            table[i, ROLL_HELD] = 1.0
            table[i, ROLL_HELD + 1], table[i, ROLL_HELD + 2] = math.cos(roll), math.sin(roll)
            table[i, ROLL_HELD + 3], table[i, ROLL_HELD + 4] = math.cos(0.5 * roll), math.sin(0.5 * roll)
        if table[i, 1] == 0.0 and table[i, 3] == 0.0:
            vh = table[i, 5] + table[i, 1] * 0.0
            vd = table[i, 7] + table[i, 3] * 0.0
            pitch = math.atan2(-vd, vh)
            table[i, PITCH_HELD] = 1.0
            table[i, PITCH_HELD + 1], table[i, PITCH_HELD + 2] = math.cos(pitch), math.sin(pitch)
            table[i, PITCH_HELD + 3], table[i, PITCH_HELD + 4] = math.cos(0.5 * pitch), math.sin(0.5 * pitch)


@compiled
def _heading_trig(table, i, psi):
    """cos, sin of the heading ``psi`` in segment i (held ones read from the table)."""
    if table[i, HEADING_HELD] != 0.0:
        return table[i, HEADING_HELD + 1], table[i, HEADING_HELD + 2]
    return math.cos(psi), math.sin(psi)


@compiled
def _segment_index(t, starts, hint):
    """Index of the segment containing time t (segments are half-open, the last is closed)."""
    i = hint
    n = starts.shape[0]
    while i + 1 < n and t >= starts[i + 1]:
        i += 1
    while i > 0 and t < starts[i]:
        i -= 1
    return i


@compiled
def _kinematics(t, table, i):
    """Closed-form motion at time t in segment i: the values needed by the integrands."""
    tau = t - table[i, 0]
    a_h, turn, a_v, roll_rate = table[i, 1], table[i, 2], table[i, 3], table[i, 4]
    vh = table[i, 5] + a_h * tau
    psi = table[i, 6] + turn * tau
    vd = table[i, 7] + a_v * tau
    roll = table[i, 8] + roll_rate * tau
    h = table[i, 9] - table[i, 7] * tau - 0.5 * a_v * tau * tau
    return vh, psi, vd, roll, h, a_h, turn, a_v, roll_rate


@compiled
def _ned_motion(t, table, i):
    """Height and north, east, down velocity at time t in segment i: what the position rates read.

    They do not depend on the latitude, so the two RK4 mid-point stages share
    them, and the last stage shares them with the rate at the end of the sample.
    """
    vh, psi, vd, roll, h, a_h, turn, a_v, rr = _kinematics(t, table, i)
    cpsi, spsi = _heading_trig(table, i, psi)
    return h, vh * cpsi, vh * spsi, vd


@compiled
def _position_rate(t, lat, table, i):
    """d(latitude)/dt, d(longitude)/dt and d(height)/dt at time t in segment i and latitude ``lat``."""
    return _rates_at(lat, _ned_motion(t, table, i))


@compiled
def _rates_at(lat, motion):
    """The position rates at latitude ``lat`` for the motion (h, v_N, v_E, v_D) of :func:`_ned_motion`."""
    h, vn, ve, vd = motion
    return earth.position_rates(lat, h, vn, ve, vd)


@compiled
def _rk4_stage(lat, step, rate, motion):
    """An RK4 stage: the position rates at ``lat + step * rate`` for the motion of the stage's time."""
    return _rates_at(lat + step * rate, motion)


# -- latitude memos ----------------------------------------------------------------------------------------------
# The functions of the latitude alone (sines, cosines, tangent, square roots and divisions of the radii and of
# gravity) are most of a position rate's and an integrand's work.  A flight along a parallel keeps its latitude to
# the last bit (profile_000 flies east: v_N = v_h cos(90 deg) ~ 1e-14 m/s), so consecutive evaluations meet the very
# same latitude again: a memo holds the last latitude's functions and gives them back when the latitude is equal
# (same value; a zero, whose sign its sine keeps, and NaN always recomputed).  The functions are earth.py's own,
# so the numbers are those of computing them every time, bit for bit.


@compiled
def _same_latitude(lat, kept):
    """True when ``lat`` is the latitude ``kept`` to the last bit, and neither a zero (whose sign its sine keeps)
    nor NaN: its functions may then be taken from a memo."""
    return lat == kept and lat != 0.0


@compiled
def _no_rate_terms():
    """An empty position-rate memo (its latitude NaN: equal to none)."""
    return (math.nan, 0.0, 0.0, 0.0)


@compiled
def _rate_terms(lat, memo):
    """(latitude, meridian radius, prime-vertical radius, cos latitude): the latitude terms of the position rates,
    from ``memo`` when it holds them."""
    if _same_latitude(lat, memo[0]):
        return memo
    cos_latitude = math.cos(lat)
    meridian, prime_vertical = earth.radii_of_curvature(lat)
    return (lat, meridian, prime_vertical, cos_latitude)


@compiled
def _rates_from_terms(terms, motion):
    """:func:`_rates_at` from the latitude terms (:func:`_rate_terms`)."""
    h, vn, ve, vd = motion
    return earth.position_rates_from_radii(terms[1], terms[2], terms[3], h, vn, ve, vd)


@compiled
def _node_terms(lat):
    """(latitude, omega_ie^n (3), tan latitude, meridian and prime-vertical radii, gravity's g0 and slope): the
    latitude terms of :func:`_integrands` (a node memo keeps them: :func:`_node_integrands`)."""
    ie_n, ie_e, ie_d = earth.earth_rate_ned(lat)
    meridian, prime_vertical = earth.radii_of_curvature(lat)
    g0, slope = earth.gravity_latitude_terms(lat)
    return (lat, ie_n, ie_e, ie_d, math.tan(lat), meridian, prime_vertical, g0, slope)


@compiled
def _rk4_sum(x, dt, k1, k2, k3, k4):
    """x one RK4 step on: x + dt/6 (k1 + 2 k2 + 2 k3 + k4)."""
    return x + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)


@compiled
def _integrands(t, lat, table, i):
    """omega_ib^b and f^b at time t (latitude supplied by the caller)."""
    return _integrands_of_motion(_kinematics(t, table, i), _node_terms(lat), table, i)


@compiled
def _integrands_of_motion(motion, terms, table, i):
    """:func:`_integrands` given the motion (:func:`_kinematics`) and the latitude terms (:func:`_node_terms`):
    a function of those and of segment i's row of the table alone."""
    vh, psi, vd, roll, h, a_h, turn, a_v, roll_rate = motion
    if table[i, HEADING_HELD] != 0.0:
        cpsi, spsi = table[i, HEADING_HELD + 1], table[i, HEADING_HELD + 2]
        chalf_y, shalf_y = table[i, HEADING_HELD + 3], table[i, HEADING_HELD + 4]
    else:
        cpsi, spsi = math.cos(psi), math.sin(psi)
        chalf_y, shalf_y = math.cos(0.5 * psi), math.sin(0.5 * psi)
    vn, ve = vh * cpsi, vh * spsi
    speed2 = vh * vh + vd * vd
    pitch_rate = (-vh * a_v + vd * a_h) / speed2
    if table[i, PITCH_HELD] != 0.0:
        cp, sp = table[i, PITCH_HELD + 1], table[i, PITCH_HELD + 2]
        chalf_p, shalf_p = table[i, PITCH_HELD + 3], table[i, PITCH_HELD + 4]
    else:
        pitch = math.atan2(-vd, vh)
        cp, sp = math.cos(pitch), math.sin(pitch)
        chalf_p, shalf_p = math.cos(0.5 * pitch), math.sin(0.5 * pitch)
    if table[i, ROLL_HELD] != 0.0:
        cr, sr = table[i, ROLL_HELD + 1], table[i, ROLL_HELD + 2]
        chalf_r, shalf_r = table[i, ROLL_HELD + 3], table[i, ROLL_HELD + 4]
    else:
        cr, sr = math.cos(roll), math.sin(roll)
        chalf_r, shalf_r = math.cos(0.5 * roll), math.sin(0.5 * roll)
    q0, q1, q2, q3 = half_angle_quaternion(chalf_r, shalf_r, chalf_p, shalf_p, chalf_y, shalf_y)
    # omega_nb^b from the Euler angle rates (ZYX sequence)
    wx = roll_rate - turn * sp
    wy = pitch_rate * cr + turn * cp * sr
    wz = -pitch_rate * sr + turn * cp * cr
    ie_n, ie_e, ie_d = terms[1], terms[2], terms[3]
    en_n, en_e, en_d = earth.transport_rate_from_radii(terms[5], terms[6], terms[4], h, vn, ve)
    # C_n^b (omega_ie + omega_en): rotate by the conjugate quaternion
    bx, by, bz = rotate_vector(q0, -q1, -q2, -q3, ie_n + en_n, ie_e + en_e, ie_d + en_d)
    # f^n = dv/dt + (2 omega_ie + omega_en) x v - g
    dvn = a_h * cpsi - vh * turn * spsi
    dve = a_h * spsi + vh * turn * cpsi
    dvd = a_v
    ox, oy, oz = 2.0 * ie_n + en_n, 2.0 * ie_e + en_e, 2.0 * ie_d + en_d
    fn = dvn + (oy * vd - oz * ve)
    fe = dve + (oz * vn - ox * vd)
    fd = dvd + (ox * ve - oy * vn) - earth.gravity_at_height(terms[7], terms[8], h)
    fx, fy, fz = rotate_vector(q0, -q1, -q2, -q3, fn, fe, fd)
    return wx + bx, wy + by, wz + bz, fx, fy, fz


@compiled
def _hermite(s, h, p0, m0, p1, m1):
    s2 = s * s
    s3 = s2 * s
    return (2 * s3 - 3 * s2 + 1) * p0 + (s3 - 2 * s2 + s) * h * m0 + (-2 * s3 + 3 * s2) * p1 + (s3 - s2) * h * m1


@compiled
def _rk4_step(table, starts, seg, k, dt, lat, lon):
    """Latitude and longitude one IMU sample on (RK4 over [k dt, (k+1) dt]), with the rates the Hermite
    interpolation of latitude needs: (lat1, lon1, rate at the start, segment at the end)."""
    k1a, k1o, _ = _position_rate(k * dt, lat, table, seg)
    return _rk4_from(table, starts, seg, k, dt, lat, lon, k1a, k1o)


@compiled
def _rk4_from(table, starts, seg, k, dt, lat, lon, k1a, k1o):
    """:func:`_rk4_step` given its first stage (the position rates at the start of the sample).

    The increments already have those rates: the rate at the end of the previous sample, the same
    function of the same time and latitude, so the same numbers (one evaluation in five saved).
    """
    t0 = k * dt
    t1 = (k + 1) * dt
    tm = t0 + 0.5 * dt
    im = _segment_index(tm, starts, seg)
    i1 = _segment_index(t1, starts, seg)
    middle = _ned_motion(tm, table, im)
    k2a, k2o, _ = _rk4_stage(lat, 0.5 * dt, k1a, middle)
    k3a, k3o, _ = _rk4_stage(lat, 0.5 * dt, k2a, middle)
    k4a, k4o, _ = _rk4_stage(lat, dt, k3a, _ned_motion(t1, table, i1))
    return _rk4_sum(lat, dt, k1a, k2a, k3a, k4a), _rk4_sum(lon, dt, k1o, k2o, k3o, k4o), k1a, i1


@compiled
def _truth_row(table, seg, t0, lat, lon, truth, rec):
    """Truth row ``rec`` at time t0 in segment ``seg``: the position given, the closed-form rest."""
    vh, psi, vd, roll, h, a_h, turn, a_v, rr = _kinematics(t0, table, seg)
    q0, q1, q2, q3 = euler_quaternion(roll, math.atan2(-vd, vh), psi)
    truth[rec, 0] = t0
    truth[rec, 1] = lat
    truth[rec, 2] = lon
    truth[rec, 3] = h
    truth[rec, 4] = vh * math.cos(psi)
    truth[rec, 5] = vh * math.sin(psi)
    truth[rec, 6] = vd
    truth[rec, 7] = q0
    truth[rec, 8] = q1
    truth[rec, 9] = q2
    truth[rec, 10] = q3


@compiled
def _truth_records(table, lat0, lon0, dt, n_samples, record_every, truth):
    """Truth rows every ``record_every`` samples (RK4 latitude/longitude on the IMU grid, closed-form rest).

    The latitude and longitude of row j are exactly those :func:`_increments`
    starts from at sample j * record_every, so increments can be generated later,
    a piece at a time, bit for bit as in one pass.
    """
    starts = table[:, 0]
    lat, lon = lat0, lon0
    seg = 0
    rec = 0
    for k in range(n_samples + 1):
        t0 = k * dt
        seg = _segment_index(t0, starts, seg)
        if k % record_every == 0:
            _truth_row(table, seg, t0, lat, lon, truth, rec)
            rec += 1
        if k == n_samples:
            break
        lat, lon, _, _ = _rk4_step(table, starts, seg, k, dt, lat, lon)
    return rec


@compiled
def _truth_motion(table, lat0, lon0, dt, n_samples, record_every, truth):
    """:func:`_truth_records` without the position integration: the closed-form columns of every row, the
    position of row 0, NaN for the other rows' latitude and longitude (the pieces' :func:`_increments` fill them)."""
    starts = table[:, 0]
    seg = 0
    rec = 0
    for k in range(0, n_samples + 1, record_every):
        t0 = k * dt
        seg = _segment_index(t0, starts, seg)
        _truth_row(table, seg, t0, lat0 if rec == 0 else math.nan, lon0 if rec == 0 else math.nan, truth, rec)
        rec += 1
    return rec


@inlined
def _weighted_sum(sums, weight, values):
    """The six running quadrature sums plus ``weight`` times the six integrand values (omega_ib^b, f^b)."""
    return (sums[0] + weight * values[0], sums[1] + weight * values[1], sums[2] + weight * values[2],
            sums[3] + weight * values[3], sums[4] + weight * values[4], sums[5] + weight * values[5])


@compiled
def _identical(a, b):
    """a and b are the same number: equal, and of the same sign when zero (NaN is identical to nothing)."""
    return a == b and math.copysign(1.0, a) == math.copysign(1.0, b)


#: columns of a node memo row (:func:`_node_integrands`): the latitude (NaN: none) and its terms (the 9 values of
#: :func:`_node_terms`), the segment and the motion (5) the integrands were computed for, the integrands (6)
MEMO_LATITUDE, MEMO_SEGMENT, MEMO_MOTION, MEMO_VALUES, MEMO_COLUMNS = 0, 9, 10, 15, 21


@inlined
def _node_integrands(t, t0, dt, lat, k1a, lat1, m1, table, i, memo, j):
    """:func:`_integrands` at time t of the sample [t0, t0 + dt] in segment i, the latitude Hermite-interpolated
    between (lat, its rate k1a) at t0 and (lat1, m1) at the sample's end; ``memo[j]`` is this node's memo.

    The integrands are a function of the latitude, the motion (ground speed, heading, down velocity, roll, height)
    and segment i; in steady flight along a parallel (a cruise) those are the same numbers node after node, and
    the memo gives the integrands back without computing them again (the latitude terms alone when only the
    motion changed).
    """
    row = memo[j]
    lat_t = _hermite((t - t0) / dt, dt, lat, k1a, lat1, m1)
    motion = _kinematics(t, table, i)
    same_latitude = _same_latitude(lat_t, row[MEMO_LATITUDE])
    if (same_latitude and row[MEMO_SEGMENT] == i and _identical(motion[0], row[MEMO_MOTION])
            and _identical(motion[1], row[MEMO_MOTION + 1]) and _identical(motion[2], row[MEMO_MOTION + 2])
            and _identical(motion[3], row[MEMO_MOTION + 3]) and _identical(motion[4], row[MEMO_MOTION + 4])):
        return (row[MEMO_VALUES], row[MEMO_VALUES + 1], row[MEMO_VALUES + 2], row[MEMO_VALUES + 3],
                row[MEMO_VALUES + 4], row[MEMO_VALUES + 5])
    if same_latitude:
        terms = (row[MEMO_LATITUDE], row[1], row[2], row[3], row[4], row[5], row[6], row[7], row[8])
    else:
        terms = _node_terms(lat_t)
        for c in range(9):
            row[MEMO_LATITUDE + c] = terms[c]
    values = _integrands_of_motion(motion, terms, table, i)
    row[MEMO_SEGMENT] = i
    for c in range(5):
        row[MEMO_MOTION + c] = motion[c]
    for c in range(6):
        row[MEMO_VALUES + c] = values[c]
    return values


@compiled
def _split_sample_increments(table, starts, seg, t0, t1, dt, lat, k1a, lat1, m1, memos):
    """(delta theta, delta v) of a sample that crosses a segment boundary: Gauss-Legendre on each part (``memos``:
    the three node memos of :func:`_node_integrands`)."""
    gl_x0 = -math.sqrt(0.6)
    gl_x2 = math.sqrt(0.6)
    gl_w0 = 5.0 / 9.0
    gl_w1 = 8.0 / 9.0
    sums = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    a = t0
    i = seg
    while a < t1:
        i = _segment_index(a, starts, i)
        b = t1
        if i + 1 < starts.shape[0] and starts[i + 1] < t1:
            b = starts[i + 1]
        half = 0.5 * (b - a)
        mid = 0.5 * (a + b)
        for node in range(3):
            if node == 0:
                x, w = gl_x0, gl_w0
            elif node == 1:
                x, w = 0.0, gl_w1
            else:
                x, w = gl_x2, gl_w0
            # nodes lie strictly inside [a, b], hence inside segment i
            values = _node_integrands(mid + half * x, t0, dt, lat, k1a, lat1, m1, table, i, memos, node)
            sums = _weighted_sum(sums, w * half, values)
        a = b
    return sums


@compiled
def _increments(table, lat0, lon0, dt, k_start, k_stop, delta_theta, delta_velocity, truth, record_every,
                fill_positions):
    """Ideal increments of samples [k_start, k_stop) into rows 0.. of the arrays, from the latitude and
    longitude at sample k_start: RK4 latitude, Gauss-Legendre increments split at segment boundaries.
    ``fill_positions``: the latitude and longitude reached at each record sample (a multiple of
    ``record_every``) are written into that row of ``truth`` (what :func:`_truth_records` computes there).

    Software-pipelined: while the three Gauss nodes of sample k are evaluated,
    the RK4 stages of sample k + 1 (a serial chain of sines, square roots and
    divisions, independent of those nodes) are interleaved with them, one stage
    between two nodes, so the processor overlaps the two.  Every number is the
    same operation on the same operands as when the samples go one after the
    other (bit for bit; tests/simulation/test_trajectory.py).  A sample within
    one segment (the common case) takes its nodes without any segment search;
    one that crosses a boundary is split (:func:`_split_sample_increments`).
    Latitude memos (the position rates', :func:`_rate_terms`) and node memos
    (each Gauss node's, :func:`_node_integrands`) give back what was computed
    for the very same inputs: in steady flight along a parallel nearly all.
    """
    starts = table[:, 0]
    gl_x0 = -math.sqrt(0.6)
    gl_x2 = math.sqrt(0.6)
    gl_w0 = 5.0 / 9.0
    gl_w1 = 8.0 / 9.0
    lat, lon = lat0, lon0
    seg = i1 = 0
    k1a = k1o = lat1 = lon1 = m1 = mo1 = 0.0
    rates = _no_rate_terms()  # latitude memos: the position rates', each Gauss node's
    memos = np.full((3, MEMO_COLUMNS), np.nan)
    if k_start < k_stop:  # the first sample's RK4: the loop then makes sample k + 1's while sample k's nodes go
        seg = _segment_index(k_start * dt, starts, seg)
        k1a, k1o, _ = _position_rate(k_start * dt, lat, table, seg)
        lat1, lon1, _, i1 = _rk4_from(table, starts, seg, k_start, dt, lat, lon, k1a, k1o)
        m1, mo1, _ = _position_rate((k_start + 1) * dt, lat1, table, i1)
    for k in range(k_start, k_stop):
        # sample k: [t0, t1] from (lat, lon, rates k1a, k1o) to (lat1, lon1, rates m1, mo1), t1 in segment i1
        t0 = k * dt
        seg = _segment_index(t0, starts, seg)
        t1 = (k + 1) * dt
        whole = i1 == seg  # the sample lies in one segment: no boundary to split at
        more = k + 1 < k_stop
        half = 0.5 * (t1 - t0)
        mid = 0.5 * (t0 + t1)
        # sample k + 1: [t1, t2] from (lat1, lon1, m1, mo1); its rate at the end is sample k + 2's first stage
        tm = t1 + 0.5 * dt
        t2 = (k + 2) * dt
        im = i2 = i1
        middle = end = (0.0, 0.0, 0.0, 0.0)
        k2a = k2o = k3a = k3o = k4a = k4o = lat2 = lon2 = m2 = mo2 = 0.0
        sums = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        if more:
            im = _segment_index(tm, starts, i1)
            i2 = _segment_index(t2, starts, i1)
            middle = _ned_motion(tm, table, im)
            rates = _rate_terms(lat1 + 0.5 * dt * m1, rates)
            k2a, k2o, _ = _rates_from_terms(rates, middle)
        if whole:
            values = _node_integrands(mid + half * gl_x0, t0, dt, lat, k1a, lat1, m1, table, seg, memos, 0)
            sums = _weighted_sum(sums, gl_w0 * half, values)
        if more:
            rates = _rate_terms(lat1 + 0.5 * dt * k2a, rates)
            k3a, k3o, _ = _rates_from_terms(rates, middle)
        if whole:
            values = _node_integrands(mid + half * 0.0, t0, dt, lat, k1a, lat1, m1, table, seg, memos, 1)
            sums = _weighted_sum(sums, gl_w1 * half, values)
        if more:
            end = _ned_motion(t2, table, i2)
            rates = _rate_terms(lat1 + dt * k3a, rates)
            k4a, k4o, _ = _rates_from_terms(rates, end)
        if whole:
            values = _node_integrands(mid + half * gl_x2, t0, dt, lat, k1a, lat1, m1, table, seg, memos, 2)
            sums = _weighted_sum(sums, gl_w0 * half, values)
        if more:
            lat2 = _rk4_sum(lat1, dt, m1, k2a, k3a, k4a)
            lon2 = _rk4_sum(lon1, dt, mo1, k2o, k3o, k4o)
            rates = _rate_terms(lat2, rates)
            m2, mo2, _ = _rates_from_terms(rates, end)
        if not whole:
            sums = _split_sample_increments(table, starts, seg, t0, t1, dt, lat, k1a, lat1, m1, memos)
        if fill_positions and (k + 1) % record_every == 0:
            truth[(k + 1) // record_every, 1] = lat1
            truth[(k + 1) // record_every, 2] = lon1
        row = k - k_start
        delta_theta[row, 0] = sums[0]
        delta_theta[row, 1] = sums[1]
        delta_theta[row, 2] = sums[2]
        delta_velocity[row, 0] = sums[3]
        delta_velocity[row, 1] = sums[4]
        delta_velocity[row, 2] = sums[5]
        lat, lon, k1a, k1o = lat1, lon1, m1, mo1
        lat1, lon1, m1, mo1, i1 = lat2, lon2, m2, mo2, i2
    return k_stop - k_start


def sample_counts(profile: FlightPath, imu_rate: float, record_rate: float) -> tuple[int, int]:
    """(IMU samples, samples per truth record) of :func:`generate_trajectory`'s flight, known before it is made."""
    if imu_rate <= 0 or record_rate <= 0:
        raise ModelError(f"profile {profile.name!r}: rates must be positive (imu {imu_rate}, record {record_rate})")
    ratio = imu_rate / record_rate
    record_every = int(round(ratio))
    if record_every < 1 or abs(ratio - record_every) > 1e-9 * ratio:
        raise ModelError(
            f"profile {profile.name!r}: IMU rate {imu_rate} Hz is not a whole multiple of the record rate {record_rate} Hz"
        )
    if not profile.segments:
        raise ModelError(f"profile {profile.name!r}: has no segments")
    return int(math.floor(profile.duration * imu_rate + 1e-6)), record_every


def generate_trajectory(profile: FlightPath, imu_rate: float, record_rate: float, streamed: bool = False,
                        positions_in_pieces: bool = False) -> Trajectory:
    """Truth at ``record_rate`` and ideal increments at ``imu_rate`` for a whole profile.

    ``imu_rate / record_rate`` must be a whole number (truth rows fall on IMU
    sample times); the flight lasts ``floor(duration * imu_rate)`` samples.
    ``streamed=True`` keeps only the truth (memory independent of the IMU rate
    and, but for the truth rows, of the duration); the increments then come
    piece by piece from :meth:`Trajectory.increments`.  ``positions_in_pieces``
    (streamed only) leaves the truth rows' latitude and longitude to those
    pieces (:class:`Trajectory`): the truth then costs next to nothing, and
    until the last piece is made only the rows reached have a position.
    """
    if positions_in_pieces and not streamed:
        raise ModelError(f"profile {profile.name!r}: positions_in_pieces needs a streamed trajectory")
    n_samples, record_every = sample_counts(profile, imu_rate, record_rate)
    table = segment_table(profile)
    n_records = n_samples // record_every + 1
    truth = np.empty((n_records, len(TRUTH_COLUMNS)))
    # a held trajectory's increments integrate the positions anyway: they fill the truth rows' (bit for bit what
    # _truth_records computes there), so the position is integrated once
    records = _truth_records if streamed and not positions_in_pieces else _truth_motion
    records(table, profile.latitude, profile.longitude, 1.0 / imu_rate, n_samples, record_every, truth)
    if streamed:
        return Trajectory(profile, float(imu_rate), record_every, None, None, truth, n_samples, positions_in_pieces)
    delta_theta = np.empty((n_samples, 3))
    delta_velocity = np.empty((n_samples, 3))
    _increments(table, profile.latitude, profile.longitude, 1.0 / imu_rate, 0, n_samples, delta_theta, delta_velocity,
                truth, record_every, True)
    return Trajectory(profile, float(imu_rate), record_every, delta_theta, delta_velocity, truth)
