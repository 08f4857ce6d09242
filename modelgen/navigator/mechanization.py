"""Strapdown mechanization at the IMU rate: fixed integration around the model's generated rates.

The navigation state is one float array ``nav`` of :data:`NAV_SIZE` entries:
the body-to-NED attitude quaternion (scalar first), the NED velocity [m/s],
latitude and longitude [rad] and height [m].  :func:`mechanize` advances it
over a run of IMU samples; the same arithmetic, line for line, is the C
navigator's (``navigator_source.c.j2``), so that both trajectories agree
to rounding.

The physics is not written here: the velocity rate without the specific force
(-(2 w_ie + w_en) x v + g), the position rates and w_in are the model's own
mechanization equations (the ones its error model is derived from), generated
as ``navigation_rates`` (:mod:`modelgen.derivation.mechanization_rates`, printed by
:mod:`modelgen.codegen.mechanization`) and passed in as ``rates``
(:func:`model_rates`).  The exact equations are flown (WGS-84 radii, normal
gravity with its free-air terms): a model's declared approximations simplify its
error model only (docs/navigation-library.md, "The navigator flies the exact equations").

Per sample k (interval t[k-1] -> t[k], dt the actual interval, so dropped
samples are bridged), the fixed, numerically delicate part:

* increments by the trapezoid rule of the bias-corrected body rates and
  specific forces: dtheta = (w[k-1] + w[k]) dt / 2, dv = (f[k-1] + f[k]) dt / 2;
* two-sample coning dtheta + dtheta_prev x dtheta / 12 and sculling
  dv + dtheta x dv / 2 + (dtheta_prev x dv + dv_prev x dtheta) / 12
  (Savage, Strapdown Analytics, ch. 7);
* velocity: v += C_b^n dv + (v' - C f)(start of the interval) dt;
* attitude: q = q(-w_in dt) * q * q(dtheta), normalized;
* position: the height from the mean of the old and new velocity, then
  latitude and longitude from the mean velocity at the mean height.
"""

from __future__ import annotations

import functools
import math
from typing import Callable

import numpy as np

from modelgen.simulation.earth import normal_gravity as gravity  # Somigliana with the free-air terms, +Down
from modelgen.simulation.earth import radii_of_curvature as radii  # R_M, R_N
from modelgen.simulation.jit import HAVE_NUMBA, compiled, compiled_in_memory

NAV_SIZE = 10  # q0 q1 q2 q3, vN vE vD, latitude, longitude, height


def model_rates(source: str, name: str) -> Callable:
    """The generated ``navigation_rates`` of a model (:func:`modelgen.codegen.mechanization.python_source`), compiled.

    Compiled with numba when it is installed (the caller :func:`mechanize` is), without its disk cache:
    the function is made from the model file at run time.
    """
    namespace: dict = {"math": math}
    exec(compile(source, f"<{name} mechanization rates>", "exec"), namespace)  # noqa: S102 - our generated code
    function = namespace["navigation_rates"]
    if not HAVE_NUMBA:
        return function
    import numba

    return numba.njit(fastmath=False, nogil=True)(function)


@functools.lru_cache(maxsize=None)
def shared_model_rates(source: str, name: str) -> Callable:
    """:func:`model_rates`, made once per process for each source and name and then shared.

    numba compiles the rates on their first call, and :func:`mechanize` once more for each rates function it
    is given (a compiled function is a type of its own): a process that makes the navigator of one model
    again (each replay, each check of a navigator) flies the same compiled code instead of compiling both
    again.  The source is the whole function, so the same source is the same rates.
    """
    return model_rates(source, name)


@compiled
def quaternion_to_dcm(q0: float, q1: float, q2: float, q3: float) -> np.ndarray:
    """C_b^n of a body-to-NED quaternion (scalar first)."""
    c = np.empty((3, 3))
    c[0, 0] = q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3
    c[0, 1] = 2.0 * (q1 * q2 - q0 * q3)
    c[0, 2] = 2.0 * (q1 * q3 + q0 * q2)
    c[1, 0] = 2.0 * (q1 * q2 + q0 * q3)
    c[1, 1] = q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3
    c[1, 2] = 2.0 * (q2 * q3 - q0 * q1)
    c[2, 0] = 2.0 * (q1 * q3 - q0 * q2)
    c[2, 1] = 2.0 * (q2 * q3 + q0 * q1)
    c[2, 2] = q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3
    return c


@compiled
def _rotation_quaternion(x: float, y: float, z: float) -> tuple[float, float, float, float]:
    """Quaternion of a rotation vector (exact half-angle form; series below 1e-8 rad)."""
    angle2 = x * x + y * y + z * z
    if angle2 < 1e-16:
        s = 0.5 - angle2 / 48.0
        return 1.0 - angle2 / 8.0, s * x, s * y, s * z
    angle = math.sqrt(angle2)
    s = math.sin(0.5 * angle) / angle
    return math.cos(0.5 * angle), s * x, s * y, s * z


@compiled
def _multiply(a0, a1, a2, a3, b0, b1, b2, b3):
    """Quaternion product a * b (scalar first)."""
    return (a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
            a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
            a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
            a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0)


@compiled_in_memory  # it takes the model's run-time compiled rates: no disk cache (see compiled_in_memory)
def mechanize(nav: np.ndarray, history: np.ndarray, time: np.ndarray, force: np.ndarray, rate: np.ndarray,
              start: int, stop: int, gyro_bias: np.ndarray, accel_bias: np.ndarray, mean_force: np.ndarray,
              gyro_scale: np.ndarray, accel_scale: np.ndarray, rates) -> None:
    """Advance ``nav`` over samples start..stop-1 (each from the sample before it), in place.

    ``force``, ``rate``: body-axis specific force and angular rate samples.
    ``history``: the previous interval's dtheta (0:3) and dv (3:6), for the
    coning and sculling terms (zeros before the first interval).
    ``mean_force``: the NED specific-force increment sum (0:3) and the time
    (3) are added to it, for the filter's operating point.
    ``gyro_scale``, ``accel_scale``: scale-factor estimates s (measured = (1 + s) true + b): the
    sensors are used as (raw - b) / (1 + s) (zeros for a model without scale-factor states).
    ``rates``: the model's generated mechanization rates (:func:`model_rates`): the physics; this
    function is the fixed integration around them.
    """
    q0, q1, q2, q3 = nav[0], nav[1], nav[2], nav[3]
    vn, ve, vd = nav[4], nav[5], nav[6]
    lat, lon, h = nav[7], nav[8], nav[9]
    pt0, pt1, pt2, pv0, pv1, pv2 = history[0], history[1], history[2], history[3], history[4], history[5]
    for k in range(start, stop):
        dt = time[k] - time[k - 1]
        t0 = (0.5 * (rate[k - 1, 0] + rate[k, 0]) - gyro_bias[0]) / (1.0 + gyro_scale[0]) * dt
        t1 = (0.5 * (rate[k - 1, 1] + rate[k, 1]) - gyro_bias[1]) / (1.0 + gyro_scale[1]) * dt
        t2 = (0.5 * (rate[k - 1, 2] + rate[k, 2]) - gyro_bias[2]) / (1.0 + gyro_scale[2]) * dt
        u0 = (0.5 * (force[k - 1, 0] + force[k, 0]) - accel_bias[0]) / (1.0 + accel_scale[0]) * dt
        u1 = (0.5 * (force[k - 1, 1] + force[k, 1]) - accel_bias[1]) / (1.0 + accel_scale[1]) * dt
        u2 = (0.5 * (force[k - 1, 2] + force[k, 2]) - accel_bias[2]) / (1.0 + accel_scale[2]) * dt
        # coning (two-sample, previous interval) and sculling with the rotation term
        c0 = t0 + (pt1 * t2 - pt2 * t1) / 12.0
        c1 = t1 + (pt2 * t0 - pt0 * t2) / 12.0
        c2 = t2 + (pt0 * t1 - pt1 * t0) / 12.0
        s0 = u0 + 0.5 * (t1 * u2 - t2 * u1) + ((pt1 * u2 - pt2 * u1) + (pv1 * t2 - pv2 * t1)) / 12.0
        s1 = u1 + 0.5 * (t2 * u0 - t0 * u2) + ((pt2 * u0 - pt0 * u2) + (pv2 * t0 - pv0 * t2)) / 12.0
        s2 = u2 + 0.5 * (t0 * u1 - t1 * u0) + ((pt0 * u1 - pt1 * u0) + (pv0 * t1 - pv1 * t0)) / 12.0
        pt0, pt1, pt2, pv0, pv1, pv2 = t0, t1, t2, u0, u1, u2
        # the model's rates (generated, ``rates``) at the start of the interval: v' - C f and w_in
        r = rates(lat, lon, h, vn, ve, vd)
        # velocity
        c = quaternion_to_dcm(q0, q1, q2, q3)
        fn = c[0, 0] * s0 + c[0, 1] * s1 + c[0, 2] * s2
        fe = c[1, 0] * s0 + c[1, 1] * s1 + c[1, 2] * s2
        fd = c[2, 0] * s0 + c[2, 1] * s1 + c[2, 2] * s2
        mean_force[0] += fn
        mean_force[1] += fe
        mean_force[2] += fd
        mean_force[3] += dt
        vn_new = vn + fn + r[0] * dt
        ve_new = ve + fe + r[1] * dt
        vd_new = vd + fd + r[2] * dt
        # attitude: body rotation, then the navigation frame's rotation
        r0, r1, r2, r3 = _rotation_quaternion(c0, c1, c2)
        q0, q1, q2, q3 = _multiply(q0, q1, q2, q3, r0, r1, r2, r3)
        n0, n1, n2, n3 = _rotation_quaternion(-r[6] * dt, -r[7] * dt, -r[8] * dt)
        q0, q1, q2, q3 = _multiply(n0, n1, n2, n3, q0, q1, q2, q3)
        norm = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
        q0, q1, q2, q3 = q0 / norm, q1 / norm, q2 / norm, q3 / norm
        # position from the mean velocity: the height first, then latitude and longitude at the mean height
        mvn, mve, mvd = 0.5 * (vn + vn_new), 0.5 * (ve + ve_new), 0.5 * (vd + vd_new)
        h_new = h + rates(lat, lon, h, mvn, mve, mvd)[5] * dt
        p = rates(lat, lon, 0.5 * (h + h_new), mvn, mve, mvd)
        lat, lon, h = lat + p[3] * dt, lon + p[4] * dt, h_new
        vn, ve, vd = vn_new, ve_new, vd_new
    nav[0], nav[1], nav[2], nav[3] = q0, q1, q2, q3
    nav[4], nav[5], nav[6] = vn, ve, vd
    nav[7], nav[8], nav[9] = lat, lon, h
    history[0], history[1], history[2], history[3], history[4], history[5] = pt0, pt1, pt2, pv0, pv1, pv2


def euler_to_dcm(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """C_b^n (body to navigation) of the aerospace z-y-x Euler angles."""
    cr, sr, cp, sp, cy, sy = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch), math.cos(yaw), math.sin(yaw)
    return np.array([[cp * cy, sr * sp * cy - cr * sy, cr * sp * cy + sr * sy],
                     [cp * sy, sr * sp * sy + cr * cy, cr * sp * sy - sr * cy],
                     [-sp, sr * cp, cr * cp]])


def dcm_to_quaternion(c: np.ndarray) -> np.ndarray:
    """Quaternion (scalar first, q0 >= 0) of a rotation matrix (Shepperd's method)."""
    trace = c[0, 0] + c[1, 1] + c[2, 2]
    candidates = [trace, c[0, 0], c[1, 1], c[2, 2]]
    i = int(np.argmax(candidates))
    if i == 0:
        s = 2.0 * math.sqrt(1.0 + trace)
        q = [0.25 * s, (c[2, 1] - c[1, 2]) / s, (c[0, 2] - c[2, 0]) / s, (c[1, 0] - c[0, 1]) / s]
    elif i == 1:
        s = 2.0 * math.sqrt(1.0 + c[0, 0] - c[1, 1] - c[2, 2])
        q = [(c[2, 1] - c[1, 2]) / s, 0.25 * s, (c[0, 1] + c[1, 0]) / s, (c[0, 2] + c[2, 0]) / s]
    elif i == 2:
        s = 2.0 * math.sqrt(1.0 + c[1, 1] - c[0, 0] - c[2, 2])
        q = [(c[0, 2] - c[2, 0]) / s, (c[0, 1] + c[1, 0]) / s, 0.25 * s, (c[1, 2] + c[2, 1]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + c[2, 2] - c[0, 0] - c[1, 1])
        q = [(c[1, 0] - c[0, 1]) / s, (c[0, 2] + c[2, 0]) / s, (c[1, 2] + c[2, 1]) / s, 0.25 * s]
    out = np.array(q)
    return out if out[0] >= 0 else -out


def dcm_to_euler(c: np.ndarray) -> tuple[float, float, float]:
    """Roll, pitch, yaw [rad] of C_b^n."""
    return (math.atan2(c[2, 1], c[2, 2]), -math.asin(max(-1.0, min(1.0, c[2, 0]))), math.atan2(c[1, 0], c[0, 0]))


def level_from_accelerometers(mean_force: np.ndarray) -> tuple[float, float]:
    """Roll and pitch [rad] of a body at rest from its mean specific force (which points up: f = -g)."""
    fx, fy, fz = (float(v) for v in mean_force)
    return math.atan2(-fy, -fz), math.atan2(fx, math.hypot(fy, fz))
