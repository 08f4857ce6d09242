"""Attitude representations: quaternions, direction cosine matrices, rotation vectors, Euler angles.

Conventions used throughout the simulation:

* quaternions are scalar-first ``[q0, q1, q2, q3]``; ``q_b^n`` rotates body
  vectors into navigation (NED) axes, so that ``C_b^n = dcm(q_b^n)``;
* a rotation vector ``phi`` is the equivalent rotation vector of the INS/GPS paper: the
  frame turns by ``|phi|`` about ``phi``; its quaternion is
  ``[cos(|phi|/2), sin(|phi|/2) phi/|phi|]``;
* Euler angles are roll, pitch, yaw about body x (forward), y (right),
  z (down): ``C_b^n = Rz(yaw) Ry(pitch) Rx(roll)``.

The compiled scalar functions return tuples so that the strapdown loop does not
allocate; the numpy functions work on stacks of attitudes for post-processing.
"""

from __future__ import annotations

import math

import numpy as np

from modelgen.simulation.jit import compiled


@compiled
def quaternion_multiply(a0, a1, a2, a3, b0, b1, b2, b3):
    """Hamilton product a (x) b, as a tuple."""
    return (
        a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
        a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
        a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
        a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0,
    )


@compiled
def rotation_vector_quaternion(x: float, y: float, z: float):
    """Quaternion of the equivalent rotation vector (x, y, z), exact for any angle.

    Below 1e-4 rad the series cos = 1 - a^2/8 + a^4/384, sin(a/2)/a = 1/2 - a^2/48
    + a^4/3840 keeps full double precision without dividing by a small angle.
    """
    a2 = x * x + y * y + z * z
    if a2 < 1e-8:
        c = 1.0 - a2 / 8.0 + a2 * a2 / 384.0
        s = 0.5 - a2 / 48.0 + a2 * a2 / 3840.0
    else:
        a = math.sqrt(a2)
        c = math.cos(0.5 * a)
        s = math.sin(0.5 * a) / a
    return c, s * x, s * y, s * z


@compiled
def quaternion_rotation_vector(q0: float, q1: float, q2: float, q3: float):
    """Rotation vector of a unit quaternion (the inverse of :func:`rotation_vector_quaternion`)."""
    if q0 < 0.0:
        q0, q1, q2, q3 = -q0, -q1, -q2, -q3
    s = math.sqrt(q1 * q1 + q2 * q2 + q3 * q3)
    if s < 1e-12:
        k = 2.0 / q0
    else:
        k = 2.0 * math.atan2(s, q0) / s
    return k * q1, k * q2, k * q3


@compiled
def rotate_vector(q0, q1, q2, q3, x, y, z):
    """C(q) v for a unit quaternion q, as a tuple."""
    # t = 2 q_vec x v ; v' = v + q0 t + q_vec x t
    tx = 2.0 * (q2 * z - q3 * y)
    ty = 2.0 * (q3 * x - q1 * z)
    tz = 2.0 * (q1 * y - q2 * x)
    return (
        x + q0 * tx + (q2 * tz - q3 * ty),
        y + q0 * ty + (q3 * tx - q1 * tz),
        z + q0 * tz + (q1 * ty - q2 * tx),
    )


@compiled
def euler_quaternion(roll: float, pitch: float, yaw: float):
    """q_b^n of Euler angles (C_b^n = Rz(yaw) Ry(pitch) Rx(roll))."""
    return half_angle_quaternion(math.cos(0.5 * roll), math.sin(0.5 * roll), math.cos(0.5 * pitch),
                                 math.sin(0.5 * pitch), math.cos(0.5 * yaw), math.sin(0.5 * yaw))


@compiled
def half_angle_quaternion(cr: float, sr: float, cp: float, sp: float, cy: float, sy: float):
    """:func:`euler_quaternion` from the cosines and sines of the half angles (a caller may hold them)."""
    return (
        cy * cp * cr + sy * sp * sr,
        cy * cp * sr - sy * sp * cr,
        cy * sp * cr + sy * cp * sr,
        sy * cp * cr - cy * sp * sr,
    )


@compiled
def misalignment(c0, c1, c2, c3, t0, t1, t2, t3):
    """psi of one computed attitude against the true one (see navigation_frame_attitude_error)."""
    d0, d1, d2, d3 = quaternion_multiply(t0, t1, t2, t3, c0, -c1, -c2, -c3)
    return quaternion_rotation_vector(d0, d1, d2, d3)


@compiled
def rotate_attitude(x, y, z, q0, q1, q2, q3):
    """q(psi) (x) q, normalized: the attitude turned by the navigation-frame rotation psi."""
    r0, r1, r2, r3 = rotation_vector_quaternion(x, y, z)
    a0, a1, a2, a3 = quaternion_multiply(r0, r1, r2, r3, q0, q1, q2, q3)
    n = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2 + a3 * a3)
    return a0 / n, a1 / n, a2 / n, a3 / n


# -- numpy, stacks of attitudes ---------------------------------------------------


def quaternion_to_dcm(q: np.ndarray) -> np.ndarray:
    """Direction cosine matrices (..., 3, 3) of unit quaternions (..., 4)."""
    q = np.asarray(q, float)
    q0, q1, q2, q3 = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        [
            np.stack([q0**2 + q1**2 - q2**2 - q3**2, 2 * (q1 * q2 - q0 * q3), 2 * (q1 * q3 + q0 * q2)], -1),
            np.stack([2 * (q1 * q2 + q0 * q3), q0**2 - q1**2 + q2**2 - q3**2, 2 * (q2 * q3 - q0 * q1)], -1),
            np.stack([2 * (q1 * q3 - q0 * q2), 2 * (q2 * q3 + q0 * q1), q0**2 - q1**2 - q2**2 + q3**2], -1),
        ],
        -2,
    )


def dcm_to_euler(C: np.ndarray) -> np.ndarray:
    """Roll, pitch, yaw [rad] (..., 3) of C_b^n matrices (..., 3, 3)."""
    C = np.asarray(C, float)
    roll = np.arctan2(C[..., 2, 1], C[..., 2, 2])
    pitch = -np.arcsin(np.clip(C[..., 2, 0], -1.0, 1.0))
    yaw = np.arctan2(C[..., 1, 0], C[..., 0, 0])
    return np.stack([roll, pitch, yaw], -1)


def quaternion_product(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of stacks of quaternions."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    a0, a1, a2, a3 = np.moveaxis(a, -1, 0)
    b0, b1, b2, b3 = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
            a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
            a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
            a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0,
        ],
        -1,
    )


def quaternion_conjugate(q: np.ndarray) -> np.ndarray:
    """Inverse of unit quaternions."""
    q = np.array(q, float)
    q[..., 1:] *= -1.0
    return q


def rotation_vectors_to_quaternions(phi: np.ndarray) -> np.ndarray:
    """Quaternions (..., 4) of rotation vectors (..., 3)."""
    phi = np.asarray(phi, float)
    angle = np.linalg.norm(phi, axis=-1)
    half = 0.5 * angle
    with np.errstate(invalid="ignore", divide="ignore"):
        k = np.where(angle < 1e-8, 0.5 - angle**2 / 48.0, np.sin(half) / np.where(angle == 0, 1.0, angle))
    return np.concatenate([np.cos(half)[..., None], k[..., None] * phi], -1)


def quaternions_to_rotation_vectors(q: np.ndarray) -> np.ndarray:
    """Rotation vectors (..., 3) of unit quaternions (..., 4), angle in [0, pi]."""
    q = np.asarray(q, float)
    q = np.where(q[..., :1] < 0, -q, q)
    s = np.linalg.norm(q[..., 1:], axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        k = np.where(s < 1e-12, 2.0 / q[..., 0], 2.0 * np.arctan2(s, q[..., 0]) / np.where(s == 0, 1.0, s))
    return k[..., None] * q[..., 1:]


def navigation_frame_attitude_error(computed: np.ndarray, true: np.ndarray) -> np.ndarray:
    """psi with C_computed = exp(-psi x) C_true: the misalignment of the computed
    navigation frame, in navigation axes (Titterton & Weston's psi angle).

    For small angles C_computed = (I - psi x) C_true; the model's own sign
    convention is applied by :mod:`modelgen.simulation.error_layout`.
    """
    delta = quaternion_product(true, quaternion_conjugate(computed))  # q(psi) = q_true (x) q_computed^-1
    return quaternions_to_rotation_vectors(delta)
