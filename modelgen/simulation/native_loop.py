"""The filter cycle out of Python: strapdown, glue and the generated C filter in one compiled loop.

The Python filter loop (:class:`~modelgen.simulation.filter_loop.FilterLoop`)
costs about 100 microseconds of interpreter and ctypes glue per filter cycle
(operating point as a dict, the layout's corrections, the measurement, the
records); over a 4-h flight at 1 Hz that is most of a correction mode's time.
Here the same cycle -- mechanize the cycle's IMU samples, correct the output,
evaluate the operating point into the C parameter struct, discretize and
predict in the generated C, form the aiding measurement, gate and update in C
(``update_masked``: its normalized innovation squared is the gate; a rejected
update is undone by restoring the filter struct's bytes), feed back or
accumulate, record -- runs in one numba-compiled function per piece of the
flight, calling the generated C through ctypes function pointers.  Python is
entered once per piece (seconds of flight), not once per cycle.

What it flies: a :class:`~modelgen.simulation.ins_aiding.NavigationQuantitySensor`
whose plug-in gives :meth:`fix_table` (the Doppler radar and the GPS
receiver), with the generated C filter (:class:`NativeFilterMaker`, what
:func:`~modelgen.simulation.filters.filter_factory` returns for ``c``).  Other
sensors and filters fly the Python loop.

Agreement with the Python loop over the same C filter: the C calls, the
mechanization and the operating-point formulas are the same operations in the
same order, so open-loop runs agree bit for bit except where the Python loop
calls BLAS or LAPACK (numpy's ``phi @ accumulated``, the norm of a corrected
quaternion, the Cholesky factor of the NEES) and this loop uses its own plain
loops; and the gate uses the C's own H, R and NIS where the Python loop
evaluates them with numpy.  tests/simulation/test_native_loop.py holds the two
to 1e-9 relative in every recorded history and equal in every count.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from modelgen.errors import ModelError
from modelgen.simulation import earth
from modelgen.simulation.filter_loop import MODES, RunResult, gate_threshold, recorded_cycles
from modelgen.simulation.filters import NativeFilter
from modelgen.simulation.jit import HAVE_NUMBA, compiled
from modelgen.simulation.rotation import misalignment, rotate_attitude
from modelgen.simulation.strapdown import _mechanize

#: operating-point quantities the compiled loop computes per cycle, by parameter name -> code
DYNAMIC_PARAMETERS = {
    "latitude": 0, "longitude": 1, "height": 2,
    "velocity_north": 3, "velocity_east": 4, "velocity_down": 5, "velocity_up": 6,
    "specific_force_north": 7, "specific_force_east": 8, "specific_force_down": 9, "specific_force_up": 10,
    "earth_radius": 11, "meridian_radius": 12, "prime_vertical_radius": 13, "gravity": 14,
    **{f"c{i + 1}{j + 1}": 15 + 3 * i + j for i in range(3) for j in range(3)},
}
CONSTANT, UNSET = -1, -2  # parameter codes: a value fixed for the flight / not supplied (the C default holds)

# measurement quantity kinds (the kinds of ins_aiding.QUANTITIES: height is formed as an angle is)
KIND_VELOCITY, KIND_ANGLE, KIND_METRES = 0, 1, 2
QUANTITY_KINDS = {"velocity": KIND_VELOCITY, "angle": KIND_ANGLE, "height": KIND_ANGLE, "metres": KIND_METRES}
# event kinds of the gate/update record
ACCEPTED, REJECTED, REFUSED_NON_FINITE, REFUSED_BY_FILTER = 0, 1, 2, 3
# status codes of the compiled piece
OK, ERR_EVALUATE, ERR_DISCRETIZE, ERR_PREDICT = 0, 1, 2, 3
# roles in a shared mechanization (MechanizationTrace)
TRACE_NONE, TRACE_WRITE, TRACE_READ = 0, 1, 2


# -- compiled pieces ---------------------------------------------------------------------------


@compiled
def _corrected(nav, dx, attitude, velocity, position, out):
    """ErrorLayout.corrected: ``nav`` with the estimated errors ``dx`` removed, into ``out``.

    Layout tables are rows (state index, axis, signed factor); the attitude
    factor includes the layout's attitude convention.
    """
    for i in range(10):
        out[i] = nav[i]
    p0 = p1 = p2 = 0.0
    for r in range(attitude.shape[0]):
        v = attitude[r, 2] * dx[int(attitude[r, 0])]
        a = int(attitude[r, 1])
        if a == 0:
            p0 += v
        elif a == 1:
            p1 += v
        else:
            p2 += v
    if p0 != 0.0 or p1 != 0.0 or p2 != 0.0:
        out[6], out[7], out[8], out[9] = rotate_attitude(p0, p1, p2, nav[6], nav[7], nav[8], nav[9])
    for r in range(velocity.shape[0]):
        out[3 + int(velocity[r, 1])] -= velocity[r, 2] * dx[int(velocity[r, 0])]
    meridian, prime_vertical = earth.radii_of_curvature(nav[0])
    for r in range(position.shape[0]):
        value = position[r, 2] * dx[int(position[r, 0])]
        a = int(position[r, 1])
        if a < 3:
            out[a] -= value
        elif a == 3:
            out[0] -= value / (meridian + nav[2])
        elif a == 4:
            out[1] -= value / ((prime_vertical + nav[2]) * math.cos(nav[0]))
        else:
            out[2] += value


@compiled
def _sensor_vector(table, dx):
    """ErrorLayout.sensor_vector: the measured-minus-true error (3,) a group's states stand for."""
    out = np.zeros(3)
    for r in range(table.shape[0]):
        out[int(table[r, 1])] += table[r, 2] * dx[int(table[r, 0])]
    return out


@compiled
def _add_sensor_states(table, error, x):
    """x += ErrorLayout.sensor_states(group, error)."""
    for r in range(table.shape[0]):
        x[int(table[r, 0])] += table[r, 2] * error[int(table[r, 1])]


@compiled
def _navigation_error(nav, truth, attitude, velocity, position, x):
    """ErrorLayout.navigation_error of ``nav`` against ``truth`` (lat, lon, h, v, q) into ``x`` (zeroed)."""
    for i in range(x.shape[0]):
        x[i] = 0.0
    psi = misalignment(nav[6], nav[7], nav[8], nav[9], truth[6], truth[7], truth[8], truth[9])
    for r in range(attitude.shape[0]):
        x[int(attitude[r, 0])] = attitude[r, 2] * psi[int(attitude[r, 1])]
    for r in range(velocity.shape[0]):
        a = int(velocity[r, 1])
        x[int(velocity[r, 0])] = velocity[r, 2] * (nav[3 + a] - truth[3 + a])
    meridian, prime_vertical = earth.radii_of_curvature(truth[0])
    d0, d1, d2 = nav[0] - truth[0], nav[1] - truth[1], nav[2] - truth[2]
    for r in range(position.shape[0]):
        a = int(position[r, 1])
        if a == 0:
            v = d0
        elif a == 1:
            v = d1
        elif a == 2:
            v = d2
        elif a == 3:
            v = d0 * (meridian + truth[2])
        elif a == 4:
            v = d1 * (prime_vertical + truth[2]) * math.cos(truth[0])
        else:
            v = -d2
        x[int(position[r, 0])] = position[r, 2] * v


@compiled
def _operating_point(nav, specific_force, enu, codes, constants, parameters):
    """aiding.operating_point, evaluated into the C parameter struct (codes: DYNAMIC_PARAMETERS, CONSTANT, UNSET)."""
    lat, h = nav[0], nav[2]
    q0, q1, q2, q3 = nav[6], nav[7], nav[8], nav[9]
    C = np.empty((3, 3))
    C[0, 0] = q0**2 + q1**2 - q2**2 - q3**2
    C[0, 1] = 2 * (q1 * q2 - q0 * q3)
    C[0, 2] = 2 * (q1 * q3 + q0 * q2)
    C[1, 0] = 2 * (q1 * q2 + q0 * q3)
    C[1, 1] = q0**2 - q1**2 + q2**2 - q3**2
    C[1, 2] = 2 * (q2 * q3 - q0 * q1)
    C[2, 0] = 2 * (q1 * q3 - q0 * q2)
    C[2, 1] = 2 * (q2 * q3 + q0 * q1)
    C[2, 2] = q0**2 - q1**2 - q2**2 + q3**2
    if enu:  # frame_matrix("ENU") @ C: rows east, north, -down
        for j in range(3):
            north, east, down = C[0, j], C[1, j], C[2, j]
            C[0, j], C[1, j], C[2, j] = east, north, -down
    meridian, prime_vertical = earth.radii_of_curvature(lat)
    values = np.empty(24)
    values[0], values[1], values[2] = lat, nav[1], h
    values[3], values[4], values[5], values[6] = nav[3], nav[4], nav[5], -nav[5]
    values[7], values[8], values[9] = specific_force[0], specific_force[1], specific_force[2]
    values[10] = -specific_force[2]
    values[11] = math.sqrt((meridian + h) * (prime_vertical + h))
    values[12], values[13] = meridian, prime_vertical
    values[14] = earth.normal_gravity(lat, h)
    for i in range(3):
        for j in range(3):
            values[15 + 3 * i + j] = C[i, j]
    for p in range(codes.shape[0]):
        c = codes[p]
        if c >= 0:
            parameters[p] = values[c]
        elif c == -1:
            parameters[p] = constants[p]


@compiled
def _correct_strapdown(state, nav):
    """Strapdown.correct: replace attitude, velocity, position; shift the extrapolation history by as much."""
    for a in range(3):
        state[16 + a] += nav[3 + a] - state[4 + a]
    state[19] += nav[0] - state[7]
    state[20] += nav[2] - state[9]
    state[7], state[8], state[9] = nav[0], nav[1], nav[2]
    state[4], state[5], state[6] = nav[3], nav[4], nav[5]
    q = nav[6:10]
    norm = math.sqrt(np.dot(q, q))  # numpy.linalg.norm's sqrt(q . q), through BLAS as there
    for a in range(4):
        state[a] = q[a] / norm


@compiled
def _nees(error, P):
    """e^T P^-1 e as the Python loop computes it (LAPACK Cholesky factor, then a solve); NaN if P is singular."""
    try:
        L = np.linalg.cholesky(P)
    except Exception:  # not positive definite (e.g. zero initial variances at t = 0)
        return math.nan
    y = np.linalg.solve(L, error)
    return np.dot(y, y)


@compiled
def _fly_piece(first, last, mode, period, n_cycles, record_every,
               delta_theta, delta_velocity, imu_offset, samples_per_cycle, ins, ins_settings, biases, specific_force, heights,
               tables, fed_back, sensor_part, enu, codes, constants,
               every, epochs_valid, epoch_velocity, epoch_position, velocity_in_body, quantities, rows, gate,
               truth, imu_errors, true_bias,
               evaluate, discretize, predict, update, get_covariance, addresses,
               parameters, x, phi, filter_bytes, P, z, mask, innovation, nis,
               accumulated, records, counters, events, trace, trace_role):
    """Filter cycles ``first``..``last`` of one correction mode (module docstring); a status code.

    Cycle 0 is only recorded (the row at t = 0).

    ``delta_theta``, ``delta_velocity``: measured increments of the piece, sample ``imu_offset`` first.
    ``ins``: the strapdown's flat state; ``ins_settings``: dt, coning code, samples per
    update, reference altitude used (1/0), damping k1, k2; ``biases``: rows gyro,
    accelerometer, sensor compensation (the strapdown's and navigator's estimates).
    ``tables``: layout tables, rows (state index, axis, factor), for attitude,
    velocity, position, gyro_constant, gyro_markov, accelerometer_constant,
    accelerometer_markov and the sensor's bias group (empty (0, 3) when absent).
    ``imu_errors``: true gyro constant, accelerometer constant (3,), gyro and
    accelerometer Markov values at record times (records, 3).
    ``records``: (times, outputs, raw outputs, estimation error, sigma, nees) rows;
    ``counters``: [next record row, updates, skipped, events]; ``events``: rows of
    (time, normalized innovation squared, kind).
    ``trace``, ``trace_role``: the mechanization shared by uncorrected modes (:class:`MechanizationTrace`):
    TRACE_NONE mechanizes, TRACE_WRITE mechanizes and writes the strapdown state and specific force after each
    cycle of the piece into ``trace`` (row k - first), TRACE_READ takes them from there instead.
    """
    attitude, velocity, position, gyro_c, gyro_m, accel_c, accel_m, bias_table = tables
    times, outputs, raw_outputs, errors, sigmas, nees_out = records
    n = x.shape[0]
    gyro_constant, accel_constant, gyro_markov, accel_markov = imu_errors
    dt, code, per_update = ins_settings[0], int(ins_settings[1]), int(ins_settings[2])
    use_reference, damping1, damping2 = ins_settings[3] > 0.5, ins_settings[4], ins_settings[5]
    raw = np.empty(10)
    corrected = np.empty(10)
    for_filter = np.empty(10)
    total = np.empty(n)
    dx = np.empty(n)
    error = np.empty(n)
    truth_row = np.empty(10)
    for k in range(first, last + 1):
        if k > 0:  # cycle 0 is the record at t = 0 only
            # advance the INS over the cycle's samples
            if trace_role == TRACE_READ:
                for i in range(ins.shape[0]):
                    ins[i] = trace[k - first, i]
                for i in range(3):
                    specific_force[i] = trace[k - first, ins.shape[0] + i]
            else:
                start = (k - 1) * samples_per_cycle - imu_offset
                if use_reference:
                    h0, h1 = heights[k - 1], heights[k]
                else:
                    h0 = h1 = math.nan
                _mechanize(ins, delta_theta, delta_velocity, start, start + samples_per_cycle, dt, code, per_update,
                           biases[0], biases[1], h0, h1, damping1, damping2, specific_force)
                if trace_role == TRACE_WRITE:
                    for i in range(ins.shape[0]):
                        trace[k - first, i] = ins[i]
                    for i in range(3):
                        trace[k - first, ins.shape[0] + i] = specific_force[i]
            raw[0], raw[1], raw[2] = ins[7], ins[8], ins[9]
            raw[3], raw[4], raw[5] = ins[4], ins[5], ins[6]
            raw[6], raw[7], raw[8], raw[9] = ins[0], ins[1], ins[2], ins[3]
            # operating point of the corrected output, transition and prediction in the C filter
            for i in range(n):
                total[i] = accumulated[i] + x[i]
            _corrected(raw, total, attitude, velocity, position, corrected)
            _operating_point(corrected, specific_force, enu, codes, constants, parameters)
            if evaluate(addresses[0], addresses[1]) != 0:
                return ERR_EVALUATE
            if discretize(addresses[1], period, addresses[2], addresses[4]) != 0:
                return ERR_DISCRETIZE
            if predict(addresses[3], addresses[2], addresses[4]) != 0:
                return ERR_PREDICT
            if mode == 2:
                stored, phi_rows, phi_cols, dense = phi  # the transition's compressed Phi, expanded (zeros stay 0)
                for e in range(stored.shape[0]):
                    dense[phi_rows[e], phi_cols[e]] = stored[e]
                carried = dense @ accumulated
                for i in range(n):
                    accumulated[i] = carried[i]
                _corrected(raw, accumulated, attitude, velocity, position, for_filter)
            else:
                for i in range(10):
                    for_filter[i] = raw[i]
            # the aiding sensor's measurement
            j = k // every
            if k % every == 0 and j < epochs_valid.shape[0]:
                t = k * period
                if not epochs_valid[j]:
                    counters[2] += 1
                else:
                    nav = for_filter
                    v0, v1, v2 = epoch_velocity[j, 0], epoch_velocity[j, 1], epoch_velocity[j, 2]
                    if velocity_in_body:
                        q0, q1, q2, q3 = nav[6], nav[7], nav[8], nav[9]
                        c00 = q0**2 + q1**2 - q2**2 - q3**2
                        c01 = 2 * (q1 * q2 - q0 * q3)
                        c02 = 2 * (q1 * q3 + q0 * q2)
                        c10 = 2 * (q1 * q2 + q0 * q3)
                        c11 = q0**2 - q1**2 + q2**2 - q3**2
                        c12 = 2 * (q2 * q3 - q0 * q1)
                        c20 = 2 * (q1 * q3 - q0 * q2)
                        c21 = 2 * (q2 * q3 + q0 * q1)
                        c22 = q0**2 - q1**2 - q2**2 + q3**2
                        v0, v1, v2 = c00 * v0 + c01 * v1 + c02 * v2, c10 * v0 + c11 * v1 + c12 * v2, c20 * v0 + c21 * v1 + c22 * v2
                    if bias_table.shape[0]:
                        b = _sensor_vector(bias_table, accumulated)
                        v0 = v0 - biases[2, 0] - b[0]
                        v1 = v1 - biases[2, 1] - b[1]
                        v2 = v2 - biases[2, 2] - b[2]
                    meridian, prime_vertical = earth.radii_of_curvature(nav[0])
                    finite = True
                    for i in range(z.shape[0]):
                        mask[i] = 0
                    for i in range(quantities.shape[0]):
                        kind, axis, sign = int(quantities[i, 0]), int(quantities[i, 1]), quantities[i, 2]
                        if kind == KIND_VELOCITY:
                            measured = v0 if axis == 0 else (v1 if axis == 1 else v2)
                            value = sign * (nav[3 + axis] - measured)
                        elif kind == KIND_ANGLE:
                            value = nav[axis] - epoch_position[j, axis]
                        else:
                            scale = meridian + nav[2] if axis == 0 else (prime_vertical + nav[2]) * math.cos(nav[0])
                            value = (nav[axis] - epoch_position[j, axis]) * scale
                        if not math.isfinite(value):
                            finite = False
                        z[rows[i]] = value
                        mask[rows[i]] = 1
                    e = counters[3]
                    events[e, 0] = t
                    events[e, 1] = math.nan
                    if not finite:
                        events[e, 2] = REFUSED_NON_FINITE
                    else:
                        snapshot = filter_bytes.copy()
                        status = update(addresses[3], z.ctypes.data, mask.ctypes.data, addresses[1],
                                        innovation.ctypes.data, nis.ctypes.data, addresses[4])
                        if status != 0:
                            events[e, 2] = REFUSED_BY_FILTER
                        elif nis[0] > gate:
                            filter_bytes[:] = snapshot
                            events[e, 1] = nis[0]
                            events[e, 2] = REJECTED
                        else:
                            events[e, 1] = nis[0]
                            events[e, 2] = ACCEPTED
                            counters[1] += 1
                            if mode != 0:
                                for i in range(n):
                                    dx[i] = x[i] if fed_back[i] else 0.0
                                if mode == 1:
                                    _corrected(raw, dx, attitude, velocity, position, corrected)
                                    _correct_strapdown(ins, corrected)
                                    g = _sensor_vector(gyro_c, dx)
                                    a = _sensor_vector(accel_c, dx)
                                    s = _sensor_vector(bias_table, dx)
                                    for i in range(3):
                                        biases[0, i] += g[i]
                                        biases[1, i] += a[i]
                                        biases[2, i] += s[i]
                                else:
                                    for i in range(n):
                                        accumulated[i] = accumulated[i] + dx[i]
                                for i in range(n):
                                    x[i] = x[i] - dx[i]
                    counters[3] += 1
        # record
        if k % record_every == 0 or k == n_cycles:
            raw[0], raw[1], raw[2] = ins[7], ins[8], ins[9]
            raw[3], raw[4], raw[5] = ins[4], ins[5], ins[6]
            raw[6], raw[7], raw[8], raw[9] = ins[0], ins[1], ins[2], ins[3]
            for i in range(n):
                total[i] = accumulated[i] + x[i]
            _corrected(raw, total, attitude, velocity, position, corrected)
            for i in range(10):
                truth_row[i] = truth[k, 1 + i]
            _navigation_error(corrected, truth_row, attitude, velocity, position, error)
            _add_sensor_states(gyro_c, gyro_constant - biases[0], error)
            _add_sensor_states(gyro_m, gyro_markov[k], error)
            _add_sensor_states(accel_c, accel_constant - biases[1], error)
            _add_sensor_states(accel_m, accel_markov[k], error)
            _add_sensor_states(bias_table, true_bias - biases[2], error)
            for i in range(n):
                if sensor_part[i]:
                    error[i] = error[i] - total[i]
            get_covariance(addresses[3], P.ctypes.data)
            row = counters[0]
            times[row] = k * period
            for i in range(10):
                outputs[row, i] = corrected[i]
                raw_outputs[row, i] = raw[i]
            for i in range(n):
                errors[row, i] = error[i]
                sigmas[row, i] = math.sqrt(max(P[i, i], 0.0))
            nees_out[row] = _nees(error, P)
            counters[0] += 1
    return OK


# -- the loop object the streaming driver steps ------------------------------------------------

MODE_CODES = {"open_loop": 0, "closed_loop": 1, "accumulated": 2}
#: correction modes that never correct their strapdown: fed the same increments, their INS are the same numbers
UNCORRECTED_MODES = ("open_loop", "accumulated")


class MechanizationTrace:
    """The strapdown states of one piece's cycles, mechanized once for every uncorrected mode.

    Open loop and accumulated correction leave the strapdown alone (only
    closed-loop feedback resets it and its IMU compensation), so, started from the same
    initial state and fed the same increments, their INS follow the same
    numbers: the first such mode of a pass (the writer) mechanizes and writes
    each cycle's strapdown state and specific force here, the others copy
    them (a 4-h 300 Hz flight: one mechanization, 0.2 s, saved per extra mode).
    """

    def __init__(self, state_size: int):
        self.rows = np.zeros((0, state_size + 3))

    def for_piece(self, first: int, last: int) -> np.ndarray:
        """The rows for cycles first..last (grown when a piece is longer than any before)."""
        if self.rows.shape[0] < last - first + 1:
            self.rows = np.zeros((last - first + 1, self.rows.shape[1]))
        return self.rows


def share_mechanization(loops: list) -> None:
    """Let the uncorrected modes among ``loops`` (stepped in list order, each piece) share one mechanization."""
    uncorrected = [loop for loop in loops if loop.mode in UNCORRECTED_MODES]
    if len(uncorrected) < 2:
        return
    trace = MechanizationTrace(uncorrected[0].navigator.strapdown.state.shape[0])
    for role, loop in zip([TRACE_WRITE] + [TRACE_READ] * (len(uncorrected) - 1), uncorrected):
        loop.trace, loop.trace_role = trace, role


def layout_table(layout: Any, group: str, convention: bool = True) -> np.ndarray:
    """Rows (state index, axis, signed factor) of one layout group (factor: convention x entry sign)."""
    s = layout.conventions.get(group, 1.0) if convention else 1.0
    entries = layout.groups.get(group, [])
    return np.array([[e.index, e.axis, s * e.sign] for e in entries], dtype=float).reshape(len(entries), 3)


def parameter_codes(parameter_names: list[str], values: dict[str, float]) -> tuple[np.ndarray, np.ndarray]:
    """Per C parameter: its DYNAMIC_PARAMETERS code, CONSTANT (value in the second array) or UNSET."""
    codes = np.full(len(parameter_names), UNSET, dtype=np.int64)
    constants = np.zeros(len(parameter_names))
    for i, name in enumerate(parameter_names):
        if name in DYNAMIC_PARAMETERS:
            codes[i] = DYNAMIC_PARAMETERS[name]
        elif name in values:
            codes[i], constants[i] = CONSTANT, float(values[name])
    return codes, constants


def native_supported(sensor: Any, make_filter: Any) -> bool:
    """True when the compiled loop can fly this sensor with this filter (else the Python loop does)."""
    return HAVE_NUMBA and hasattr(make_filter, "native") and hasattr(sensor, "fix_table") and hasattr(sensor, "native_loop")


class NativeFilterLoop:
    """One correction mode flown by the compiled loop, a piece at a time (:meth:`run`); ``result`` as FilterLoop's.

    ``navigator`` is a :class:`~modelgen.simulation.ins_aiding.StrapdownNavigator`
    (its strapdown, layout, sensor record and measurement mapping are read, and
    its strapdown state is advanced in place); ``parameter_values`` the
    operating point's full vocabulary at the start (the constants among them:
    noise, IMU budget, earth rate, are used for the whole flight).
    """

    def __init__(self, navigator: Any, native: NativeFilter, mode: str, n_cycles: int, period: float,
                 fed_back: np.ndarray, gate_probability: float, parameter_values: dict[str, float],
                 record_every: int = 1, progress: Any = None):
        if mode not in MODES:
            raise ModelError(f"filter loop: unknown correction mode {mode!r} (choose from {', '.join(MODES)})")
        if record_every < 1:
            raise ModelError(f"filter loop: record_every must be a positive whole number, got {record_every}")
        self.navigator, self.native, self.mode, self.n_cycles, self.period = navigator, native, mode, n_cycles, period
        self.record_every, self.progress = record_every, progress
        layout, sensors, sensor = navigator.layout, navigator.sensors, navigator.sensor
        n = layout.n
        self.fed_back = np.asarray(fed_back, dtype=np.bool_)
        sensor_part = np.ones(n, np.bool_)
        for group in ("attitude", "velocity", "position"):
            sensor_part[layout.indices(group)] = False
        self.sensor_part = sensor_part
        self.tables = tuple(layout_table(layout, g, g not in ("velocity", "position")) for g in
                            ("attitude", "velocity", "position", "gyro_constant", "gyro_markov",
                             "accelerometer_constant", "accelerometer_markov"))
        bias = layout_table(layout, sensor.bias_group) if sensor.bias_group else np.zeros((0, 3))
        self.tables += (bias,)
        strapdown = navigator.strapdown
        self.codes, self.constants = parameter_codes([name for name, _ in native.compiled.params._fields_],
                                                     parameter_values)
        damping = strapdown.vertical_damping
        self.ins_settings = np.array([strapdown.dt, strapdown.code, strapdown.samples_per_update,
                                      0.0 if damping is None else 1.0,
                                      0.0 if damping is None else damping.k1, 0.0 if damping is None else damping.k2])
        self.biases = np.zeros((3, 3))
        self.biases[0], self.biases[1] = strapdown.gyro_bias, strapdown.accel_bias
        record = sensors.aiding
        velocity, position, in_body = sensor.fix_table(record)
        self.epoch_velocity, self.epoch_position, self.velocity_in_body = velocity, position, bool(in_body)
        self.epochs_valid = np.asarray(record.valid, dtype=np.bool_)
        self.quantities = np.array([[QUANTITY_KINDS[kind], axis, sign] for kind, axis, sign in navigator.quantities],
                                   dtype=float).reshape(len(navigator.quantities), 3)
        self.rows = np.asarray(navigator.rows, dtype=np.int64)
        self.gate = gate_threshold(gate_probability, len(self.rows))
        self.true_bias = np.asarray(sensor.true_bias(record), dtype=float)
        nm = max(native.compiled.nm, 1)
        self.P = np.zeros((n, n))
        self.z, self.mask = np.zeros(nm), np.zeros(nm, dtype=np.uint8)
        self.innovation, self.nis = np.zeros(nm), np.zeros(1)
        self.accumulated = np.zeros(n)
        rows = len(recorded_cycles(n_cycles, record_every))
        self.result = RunResult(mode, "generated-c", np.zeros(rows), np.zeros((rows, 10)), np.zeros((rows, 10)),
                                np.zeros((rows, n)), np.zeros((rows, n)), np.full(rows, math.nan))
        self.counters = np.zeros(4, dtype=np.int64)
        self.trace: MechanizationTrace | None = None  # set by share_mechanization
        self.trace_role = TRACE_NONE
        self._entry = None  # the compiled overload of _fly_piece, once known (see _call)
        self._run(0, 0)  # the record at t = 0 (cycle 0 only records)

    _NO_TRACE = np.zeros((0, 0))

    def _run(self, first: int, last: int) -> None:
        nav, sensors, native, r = self.navigator, self.navigator.sensors, self.native, self.result
        events = np.zeros((last - first + 2, 3))
        self.counters[3] = 0
        errors = sensors.imu_errors
        empty = np.zeros((0, 3))  # cycle 0 (the record at t = 0) comes before any piece
        args = (
            first, last, MODE_CODES[self.mode], self.period, self.n_cycles, self.record_every,
            empty if sensors.delta_theta is None else sensors.delta_theta,
            empty if sensors.delta_velocity is None else sensors.delta_velocity, sensors.sample_offset, nav.samples_per_cycle, nav.strapdown.state, self.ins_settings, self.biases,
            nav.strapdown.specific_force, sensors.altitude_reference,
            self.tables, self.fed_back, self.sensor_part, nav.frame.upper() == "ENU", self.codes, self.constants,
            nav.every, self.epochs_valid, self.epoch_velocity, self.epoch_position, self.velocity_in_body,
            self.quantities, self.rows, self.gate,
            sensors.trajectory.truth, (np.asarray(errors.gyro_constant, float), np.asarray(errors.accel_constant, float),
                                       errors.gyro_markov, errors.accel_markov), self.true_bias,
            *native.functions, native.addresses, native.parameters, native.state, native.transition_matrix,
            native.filter_bytes, self.P, self.z, self.mask, self.innovation, self.nis,
            self.accumulated, (r.times, r.outputs, r.raw_outputs, r.estimation_error, r.sigma, r.nees),
            self.counters, events, self._NO_TRACE if self.trace is None else self.trace.for_piece(first, last),
            self.trace_role)
        status = self._call(args)
        if status != OK:
            what = {ERR_EVALUATE: "matrices_evaluate", ERR_DISCRETIZE: f"discretize (T = {self.period})",
                    ERR_PREDICT: "predict"}[status]
            raise ModelError(f"generated C filter refused {what} in cycles {first}..{last}")
        r.updates = int(self.counters[1])
        r.skipped = int(self.counters[2])
        for t, d2, kind in events[: self.counters[3]]:
            if kind == REFUSED_NON_FINITE:
                r.refused.append(float(t))
                continue
            r.innovations.append((float(t), float(d2)))
            if kind == REJECTED:
                r.rejected.append(float(t))
            elif kind == REFUSED_BY_FILTER:
                r.refused.append(float(t))
        nav.strapdown.gyro_bias[:] = self.biases[0]
        nav.strapdown.accel_bias[:] = self.biases[1]
        nav.sensor_compensation[:] = self.biases[2]

    @property
    def recorded(self) -> int:
        """Rows of ``result`` recorded so far."""
        return int(self.counters[0])

    def _call(self, args: tuple) -> int:
        """``_fly_piece(*args)``; after the first call straight into its compiled entry point.

        numba's dispatcher types every argument on every call, and for tuples
        and ctypes function pointers it does so in Python: about 3 ms for this
        call's fifty arguments, more than the 10-s piece's cycles cost.  The
        argument types never change within a flight, so the overload is looked
        up once (from the types numba itself gives the arguments).
        """
        pieces_fit = all(a.dtype == np.float64 and a.ndim == 2 and a.flags.c_contiguous for a in args[6:8])
        if self._entry is not None and pieces_fit:  # the IMU pieces are the only arguments not made here
            return self._entry(*args)
        status = _fly_piece(*args)
        overloads = getattr(_fly_piece, "overloads", None)
        if overloads is not None and pieces_fit:
            signature = tuple(_fly_piece.typeof_pyval(a) for a in args)
            compiled_overload = overloads.get(signature)
            self._entry = getattr(compiled_overload, "entry_point", None)
        return status

    def run(self, first: int, last: int) -> None:
        """Filter cycles ``first``..``last`` (consecutive pieces, in order)."""
        self._run(first, last)
        if self.progress is not None:
            self.progress(last, self.n_cycles)
