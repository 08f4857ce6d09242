"""Strapdown mechanization in the local-level (NED) navigation frame.

Attitude is a quaternion q_b^n updated with the equivalent rotation vector
(the INS/GPS paper, §3.1): every N IMU samples (the rotation-vector update period N T)
the rotation vector phi of the body over that period is built from the N angle
increments with a coning correction, and the navigation frame's own rotation
zeta = (omega_ie^n + omega_en^n) N T is removed:

    q(k) = q(-zeta) (x) q(k-1) (x) q(phi).

Coning algorithms (Savage 1998; Qin Yongyuan, *Inertial Navigation*, 2006):

* ``none``   phi = sum of increments (no coning term), N = 1;
* ``single`` single-sample with the previous sample, N = 1:
  phi = dth_k + 1/12 dth_{k-1} x dth_k;
* ``two``    phi = th1 + th2 + 2/3 th1 x th2, N = 2;
* ``three``  phi = sum + 9/20 th1 x th3 + 27/40 th2 x (th3 - th1), N = 3 (Miller 1983);
* ``four``   phi = sum + 214/315 (th1 x th2 + th2 x th3 + th3 x th4)
  + 46/105 (th1 x th3 + th2 x th4) + 54/105 th1 x th4, N = 4.

The coefficients are those that make the pure-coning error of an N-sample
update of length h = N T vanish up to (Omega h)^(2N+1): matching the expansion
of the exact coning term 1/2 sin^2(a) (Omega h - sin Omega h) with
th_i x th_j = sin^2(a) 4 sin^2(Omega T/2) sin((j-i) Omega T) gives, per lag
j - i, the summed coefficients 2/3 (N = 2); 9/8 and 9/20 (N = 3, lags 1, 2);
214/105, 92/105, 54/105 (N = 4, lags 1, 2, 3).  Only the per-lag sums are fixed
by pure coning; they are split equally over the pairs of the same lag.  (Tables
that print 33/80, 57/80 for N = 3 or 736/945 ... for N = 4 give one order less
under pure coning -- checked numerically by the coning test, which drives
this module's own mechanization, ``_mechanize``, with a coning motion.)

Velocity uses the same samples: the body velocity increment is
dv + 1/2 th x dv (rotation compensation) + the sculling term, which has the
coning term's coefficients with every a x b replaced by a_th x b_v + a_v x b_th.
It is resolved in navigation axes with (I - 1/2 zeta x) C_b^n(k-1), and gravity
and Coriolis  [g^n - (2 omega_ie^n + omega_en^n) x v^n] N T  are added with
the earth quantities taken at the extrapolated mid-period position and velocity.
Latitude, longitude and height follow by the trapezoidal rule.  The vertical
channel, which diverges in a free inertial system (the core paper ignores it), can be
damped with a reference (barometric) altitude by a second-order loop.

The loop is compiled (:mod:`modelgen.simulation.jit`); its state lives in a
flat float array so that a Python wrapper can stop it between filter cycles,
read it and feed corrections back.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from modelgen.errors import ModelError
from modelgen.simulation import earth
from modelgen.simulation.jit import compiled
from modelgen.simulation.rotation import (
    quaternion_multiply,
    rotate_vector,
    rotation_vector_quaternion,
)

#: coning/sculling algorithm name -> (code, samples per rotation-vector update)
ALGORITHMS = {"none": (0, 1), "single": (1, 1), "two": (2, 2), "three": (3, 3), "four": (4, 4)}

# Flat state layout.
Q, V, LAT, LON, HGT = 0, 4, 7, 8, 9
PREV_DTHETA, PREV_DVEL = 10, 13  # last sample's increments (single-sample algorithm)
PREV_V, PREV_LAT, PREV_HGT = 16, 19, 20  # values one update earlier (mid-point extrapolation)
HAVE_PREVIOUS = 21
STATE_SIZE = 22


@compiled
def _cross(ax, ay, az, bx, by, bz):
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@compiled
def _pair(th, dv, i, j, with_velocity):
    """th_i x th_j and, if asked, the sculling pair th_i x v_j + v_i x th_j."""
    cx, cy, cz = _cross(th[i, 0], th[i, 1], th[i, 2], th[j, 0], th[j, 1], th[j, 2])
    if not with_velocity:
        return cx, cy, cz, 0.0, 0.0, 0.0
    sx, sy, sz = _cross(th[i, 0], th[i, 1], th[i, 2], dv[j, 0], dv[j, 1], dv[j, 2])
    ux, uy, uz = _cross(dv[i, 0], dv[i, 1], dv[i, 2], th[j, 0], th[j, 1], th[j, 2])
    return cx, cy, cz, sx + ux, sy + uy, sz + uz


@compiled
def _coning_sculling(th, dv, code, prev_th, prev_dv, have_previous, with_velocity):
    """Coning correction to the rotation vector and sculling correction to dv (body axes).

    ``th``/``dv`` hold the N samples of this update in rows 0..N-1.
    """
    c0 = c1 = c2 = s0 = s1 = s2 = 0.0
    if code == 1:
        if have_previous:
            # 1/12 (dth_{k-1} x dth_k), 1/12 (dth_{k-1} x dv_k + dv_{k-1} x dth_k)
            c0, c1, c2 = _cross(prev_th[0], prev_th[1], prev_th[2], th[0, 0], th[0, 1], th[0, 2])
            if with_velocity:
                a0, a1, a2 = _cross(prev_th[0], prev_th[1], prev_th[2], dv[0, 0], dv[0, 1], dv[0, 2])
                b0, b1, b2 = _cross(prev_dv[0], prev_dv[1], prev_dv[2], th[0, 0], th[0, 1], th[0, 2])
                s0, s1, s2 = a0 + b0, a1 + b1, a2 + b2
            k = 1.0 / 12.0
            c0, c1, c2, s0, s1, s2 = k * c0, k * c1, k * c2, k * s0, k * s1, k * s2
    elif code == 2:
        c0, c1, c2, s0, s1, s2 = _pair(th, dv, 0, 1, with_velocity)
        k = 2.0 / 3.0
        c0, c1, c2, s0, s1, s2 = k * c0, k * c1, k * c2, k * s0, k * s1, k * s2
    elif code == 3:
        a = _pair(th, dv, 0, 2, with_velocity)
        b = _pair(th, dv, 1, 2, with_velocity)
        d = _pair(th, dv, 1, 0, with_velocity)  # th2 x (th3 - th1) = th2 x th3 - th2 x th1
        ka, kb = 9.0 / 20.0, 27.0 / 40.0
        c0 = ka * a[0] + kb * (b[0] - d[0])
        c1 = ka * a[1] + kb * (b[1] - d[1])
        c2 = ka * a[2] + kb * (b[2] - d[2])
        s0 = ka * a[3] + kb * (b[3] - d[3])
        s1 = ka * a[4] + kb * (b[4] - d[4])
        s2 = ka * a[5] + kb * (b[5] - d[5])
    elif code == 4:
        p12 = _pair(th, dv, 0, 1, with_velocity)
        p34 = _pair(th, dv, 2, 3, with_velocity)
        p13 = _pair(th, dv, 0, 2, with_velocity)
        p24 = _pair(th, dv, 1, 3, with_velocity)
        p14 = _pair(th, dv, 0, 3, with_velocity)
        p23 = _pair(th, dv, 1, 2, with_velocity)
        k1, k2, k3 = 214.0 / 315.0, 46.0 / 105.0, 54.0 / 105.0
        c0 = k1 * (p12[0] + p23[0] + p34[0]) + k2 * (p13[0] + p24[0]) + k3 * p14[0]
        c1 = k1 * (p12[1] + p23[1] + p34[1]) + k2 * (p13[1] + p24[1]) + k3 * p14[1]
        c2 = k1 * (p12[2] + p23[2] + p34[2]) + k2 * (p13[2] + p24[2]) + k3 * p14[2]
        s0 = k1 * (p12[3] + p23[3] + p34[3]) + k2 * (p13[3] + p24[3]) + k3 * p14[3]
        s1 = k1 * (p12[4] + p23[4] + p34[4]) + k2 * (p13[4] + p24[4]) + k3 * p14[4]
        s2 = k1 * (p12[5] + p23[5] + p34[5]) + k2 * (p13[5] + p24[5]) + k3 * p14[5]
    return c0, c1, c2, s0, s1, s2


@compiled
def _mechanize(state, delta_theta, delta_velocity, start, stop, dt, code, samples_per_update,
               gyro_bias, accel_bias, reference_height0, reference_height1, damping1, damping2, specific_force):
    """Advance ``state`` over samples [start, stop); see the module docstring.

    gyro_bias / accel_bias: estimated sensor errors (measured minus true, rad/s and
    m/s^2, body axes) subtracted from every increment.  reference_height0/1: the
    reference altitude at the chunk's start and end (NaN = free vertical channel);
    damping1/damping2: the loop gains k1 [1/s] and k2 [1/s^2].  specific_force
    receives the mean specific force in navigation axes over the chunk.
    """
    N = samples_per_update
    T = N * dt
    th = np.zeros((4, 3))
    dv = np.zeros((4, 3))
    prev_th = state[PREV_DTHETA:PREV_DTHETA + 3].copy()
    prev_dv = state[PREV_DVEL:PREV_DVEL + 3].copy()
    q0, q1, q2, q3 = state[0], state[1], state[2], state[3]
    vn, ve, vd = state[4], state[5], state[6]
    lat, lon, h = state[7], state[8], state[9]
    pvn, pve, pvd = state[16], state[17], state[18]
    plat, phgt = state[19], state[20]
    have_previous = state[HAVE_PREVIOUS] > 0.5
    use_reference = not math.isnan(reference_height0)
    sf_n = sf_e = sf_d = 0.0
    n_updates = (stop - start) // N
    for u in range(n_updates):
        base = start + u * N
        sx = sy = sz = wx = wy = wz = 0.0
        for j in range(N):
            for a in range(3):
                th[j, a] = delta_theta[base + j, a] - gyro_bias[a] * dt
                dv[j, a] = delta_velocity[base + j, a] - accel_bias[a] * dt
            sx += th[j, 0]
            sy += th[j, 1]
            sz += th[j, 2]
            wx += dv[j, 0]
            wy += dv[j, 1]
            wz += dv[j, 2]
        c0, c1, c2, s0, s1, s2 = _coning_sculling(th, dv, code, prev_th, prev_dv, have_previous, True)
        rx, ry, rz = _cross(sx, sy, sz, wx, wy, wz)
        bvx = wx + 0.5 * rx + s0
        bvy = wy + 0.5 * ry + s1
        bvz = wz + 0.5 * rz + s2
        # mid-period extrapolation of the quantities the earth model needs
        if have_previous:
            mlat = lat + 0.5 * (lat - plat)
            mh = h + 0.5 * (h - phgt)
            mvn = vn + 0.5 * (vn - pvn)
            mve = ve + 0.5 * (ve - pve)
            mvd = vd + 0.5 * (vd - pvd)
        else:
            mlat, mh, mvn, mve, mvd = lat, h, vn, ve, vd
        ie_n, ie_e, ie_d = earth.earth_rate_ned(mlat)
        en_n, en_e, en_d = earth.transport_rate_ned(mlat, mh, mvn, mve)
        zx, zy, zz = (ie_n + en_n) * T, (ie_e + en_e) * T, (ie_d + en_d) * T
        g = earth.normal_gravity(mlat, mh)
        # specific-force velocity increment in navigation axes
        fx, fy, fz = rotate_vector(q0, q1, q2, q3, bvx, bvy, bvz)
        cx, cy, cz = _cross(zx, zy, zz, fx, fy, fz)
        fx, fy, fz = fx - 0.5 * cx, fy - 0.5 * cy, fz - 0.5 * cz
        sf_n += fx
        sf_e += fy
        sf_d += fz
        ox, oy, oz = 2.0 * ie_n + en_n, 2.0 * ie_e + en_e, 2.0 * ie_d + en_d
        kx, ky, kz = _cross(ox, oy, oz, mvn, mve, mvd)
        nvn = vn + fx - kx * T
        nve = ve + fy - ky * T
        nvd = vd + fz + (g - kz) * T
        if use_reference:
            frac = (base + 0.5 * N - start) / (stop - start)
            href = reference_height0 + frac * (reference_height1 - reference_height0)
            dh = h - href
            nvd += damping2 * dh * T
        meridian, prime_vertical = earth.radii_of_curvature(mlat)
        nlat = lat + T * 0.5 * (vn + nvn) / (meridian + mh)
        nlon = lon + T * 0.5 * (ve + nve) / ((prime_vertical + mh) * math.cos(mlat))
        nh = h - T * 0.5 * (vd + nvd)
        if use_reference:
            nh -= damping1 * dh * T
        # attitude: body rotation (right) and navigation-frame rotation (left)
        r0, r1, r2, r3 = rotation_vector_quaternion(sx + c0, sy + c1, sz + c2)
        q0, q1, q2, q3 = quaternion_multiply(q0, q1, q2, q3, r0, r1, r2, r3)
        r0, r1, r2, r3 = rotation_vector_quaternion(-zx, -zy, -zz)
        q0, q1, q2, q3 = quaternion_multiply(r0, r1, r2, r3, q0, q1, q2, q3)
        norm = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
        q0, q1, q2, q3 = q0 / norm, q1 / norm, q2 / norm, q3 / norm
        pvn, pve, pvd, plat, phgt = vn, ve, vd, lat, h
        vn, ve, vd, lat, lon, h = nvn, nve, nvd, nlat, nlon, nh
        for a in range(3):
            prev_th[a] = th[N - 1, a]
            prev_dv[a] = dv[N - 1, a]
        have_previous = True
    state[0], state[1], state[2], state[3] = q0, q1, q2, q3
    state[4], state[5], state[6] = vn, ve, vd
    state[7], state[8], state[9] = lat, lon, h
    state[16], state[17], state[18] = pvn, pve, pvd
    state[19], state[20] = plat, phgt
    state[HAVE_PREVIOUS] = 1.0 if have_previous else 0.0
    for a in range(3):
        state[PREV_DTHETA + a] = prev_th[a]
        state[PREV_DVEL + a] = prev_dv[a]
    duration = n_updates * T
    if duration > 0:
        specific_force[0] = sf_n / duration
        specific_force[1] = sf_e / duration
        specific_force[2] = sf_d / duration
    return n_updates * N


@dataclass
class VerticalDamping:
    """Second-order barometric damping of the vertical channel.

    h' = -v_d - k1 (h - h_ref),  v_d' = ... + k2 (h - h_ref); natural frequency
    sqrt(k2) must dominate the 2 g / R ~ 3e-6 s^-2 instability.  Defaults: a
    100-s loop (omega0 = 0.01 rad/s, k2 = omega0^2) critically-damped-ish
    (k1 = 2 zeta omega0 with zeta = 0.707).
    """

    k1: float = 2 * 0.707 * 0.01
    k2: float = 0.01**2


class Strapdown:
    """The mechanization with its state; a thin stateful wrapper around the compiled loop."""

    def __init__(self, initial: np.ndarray, imu_rate: float, algorithm: str = "two",
                 vertical_damping: VerticalDamping | None = VerticalDamping()):
        if algorithm not in ALGORITHMS:
            raise ModelError(f"strapdown: unknown coning algorithm {algorithm!r} (choose from {', '.join(ALGORITHMS)})")
        initial = np.asarray(initial, float)
        if initial.shape != (10,) or not np.all(np.isfinite(initial)):
            raise ModelError("strapdown: the initial state must be 10 finite numbers (lat, lon, h, v_NED, q_b^n)")
        self.code, self.samples_per_update = ALGORITHMS[algorithm]
        self.algorithm = algorithm
        self.dt = 1.0 / imu_rate
        self.vertical_damping = vertical_damping
        self.state = np.zeros(STATE_SIZE)
        self.state[LAT], self.state[LON], self.state[HGT] = initial[0], initial[1], initial[2]
        self.state[V:V + 3] = initial[3:6]
        q = initial[6:10]
        self.state[Q:Q + 4] = q / np.linalg.norm(q)
        self.gyro_bias = np.zeros(3)  # estimated gyro error (measured - true) [rad/s]
        self.accel_bias = np.zeros(3)  # estimated accelerometer error (measured - true) [m/s^2]
        self.specific_force = np.zeros(3)

    # -- running ---------------------------------------------------------------
    def run(self, delta_theta: np.ndarray, delta_velocity: np.ndarray, start: int, stop: int,
            reference_height: tuple[float, float] | None = None) -> None:
        """Mechanize samples [start, stop); the count must be a multiple of the update's N."""
        if (stop - start) % self.samples_per_update:
            raise ModelError(
                f"strapdown: {stop - start} samples is not a multiple of the {self.algorithm}-sample update ({self.samples_per_update})"
            )
        if reference_height is None or self.vertical_damping is None:
            h0 = h1 = math.nan
            k1 = k2 = 0.0
        else:
            h0, h1 = reference_height
            k1, k2 = self.vertical_damping.k1, self.vertical_damping.k2
        _mechanize(self.state, delta_theta, delta_velocity, start, stop, self.dt, self.code,
                   self.samples_per_update, self.gyro_bias, self.accel_bias, h0, h1, k1, k2, self.specific_force)

    # -- reading ---------------------------------------------------------------
    @property
    def quaternion(self) -> np.ndarray:
        return self.state[Q:Q + 4].copy()

    @property
    def velocity(self) -> np.ndarray:
        return self.state[V:V + 3].copy()

    @property
    def position(self) -> np.ndarray:
        """latitude, longitude [rad], height [m]."""
        return self.state[LAT:HGT + 1].copy()

    def navigation_state(self) -> np.ndarray:
        """lat, lon, h, v_NED, q_b^n: the layout of :meth:`Trajectory.initial_state`."""
        return np.concatenate([self.position, self.velocity, self.quaternion])

    # -- closed-loop feedback -------------------------------------------------------
    def correct(self, navigation_state: np.ndarray) -> None:
        """Replace attitude, velocity and position by corrected values (feedback).

        The extrapolation history is shifted by the same amount so that the next
        mid-point extrapolation is not disturbed by the jump.
        """
        s = self.state
        shift_v = navigation_state[3:6] - s[V:V + 3]
        s[PREV_V:PREV_V + 3] += shift_v
        s[PREV_LAT] += navigation_state[0] - s[LAT]
        s[PREV_HGT] += navigation_state[2] - s[HGT]
        s[LAT], s[LON], s[HGT] = navigation_state[0], navigation_state[1], navigation_state[2]
        s[V:V + 3] = navigation_state[3:6]
        q = navigation_state[6:10]
        s[Q:Q + 4] = q / np.linalg.norm(q)
