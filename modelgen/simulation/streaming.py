"""Flying a flight in pieces: memory independent of its duration, several correction modes in one pass.

A streamed trajectory (:func:`~modelgen.simulation.trajectory.generate_trajectory`
with ``streamed=True``) holds only the truth rows; its sensors
(:func:`~modelgen.simulation.flight.simulate_sensors`) hold the IMU errors as a
replayable :class:`~modelgen.simulation.imu.ImuErrorStream`.  :func:`fly_modes`
then walks the flight a piece at a time (``piece_seconds`` of IMU data, a whole
number of filter cycles): it generates the piece's ideal increments, corrupts
them, and steps every requested correction mode's filter loop through the
piece's cycles before the next piece replaces it.  The modes therefore share
one pass over the data (what ``modelgen simulate`` flies); the next piece's
ideal increments are generated in a second thread (compiled code that
releases the GIL) while the current one flies.  What is held is
a piece of IMU data, the truth and sensor records at the filter and sensor
rates, and the histories at the rate asked for (``record_every``).

Results are bit for bit those of flying a held trajectory (same seed, any
piece length): tests/simulation/test_streaming.py checks both.
"""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Callable, Iterable

import numpy as np

from modelgen.derive.symbolic import DerivedModel
from modelgen.errors import ModelError
from modelgen.simulation.aiding import FilterMaker, Progress, SensorData
from modelgen.simulation.error_layout import ErrorLayout
from modelgen.simulation.filter_loop import RunResult
from modelgen.simulation.native_loop import native_supported
from modelgen.simulation.scenario import FlightProfile
from modelgen.simulation.trajectory import Trajectory

#: default piece length: 10 s of IMU data (3,000 samples at 300 Hz, 144 kB of increments)
PIECE_SECONDS = 10.0
#: at most this many history rows per correction mode in a report (a longer flight keeps every k-th cycle)
MAX_HISTORY_ROWS = 20000

Sink = Callable[[int, RunResult, int], None]
#: who runs the cycle between IMU samples and filter: the compiled loop where possible, or the Python loop
GLUES = ("compiled", "python")


def cycles_per_piece(trajectory: Trajectory, piece_seconds: float) -> int:
    """Whole filter cycles in a piece of about ``piece_seconds`` (at least one)."""
    if not (math.isfinite(piece_seconds) and piece_seconds > 0):
        raise ModelError(f"streaming: the piece length must be a positive number of seconds, got {piece_seconds!r}")
    return max(1, int(round(piece_seconds / trajectory.record_period)))


def history_every(n_cycles: int, max_rows: int = MAX_HISTORY_ROWS) -> int:
    """``record_every`` keeping at most about ``max_rows`` history rows over ``n_cycles`` filter cycles."""
    return max(1, math.ceil(n_cycles / max_rows))


def pieces(n_cycles: int, per_piece: int) -> Iterable[tuple[int, int]]:
    """Consecutive ranges [first, last] of filter cycles 1..n_cycles, ``per_piece`` at a time."""
    for first in range(1, n_cycles + 1, per_piece):
        yield first, min(first + per_piece - 1, n_cycles)


def piece_samples(trajectory: Trajectory, first_cycle: int, last_cycle: int) -> tuple[int, int]:
    """IMU samples [start, stop) of filter cycles [first_cycle, last_cycle]."""
    every = trajectory.record_every
    return (first_cycle - 1) * every, last_cycle * every


def ideal_piece(trajectory: Trajectory, first_cycle: int, last_cycle: int) -> tuple[np.ndarray, np.ndarray]:
    """Ideal increments of filter cycles [first_cycle, last_cycle] (generated now for a streamed trajectory)."""
    return trajectory.increments(*piece_samples(trajectory, first_cycle, last_cycle))


def load_piece(sensors: SensorData, cursor, first_cycle: int, last_cycle: int,
               ideal: tuple[np.ndarray, np.ndarray] | None = None) -> None:
    """Put the measured increments of cycles [first_cycle, last_cycle] into ``sensors`` (streamed sensors).

    ``ideal``: the piece's ideal increments if already made (by a prefetch), else they are made now.
    """
    trajectory = sensors.trajectory
    start, _ = piece_samples(trajectory, first_cycle, last_cycle)
    if cursor.position != start:
        raise ModelError(f"streaming: pieces must come in order (expected sample {cursor.position}, got {start})")
    ideal_theta, ideal_velocity = ideal if ideal is not None else ideal_piece(trajectory, first_cycle, last_cycle)
    sensors.delta_theta, sensors.delta_velocity = cursor.corrupt(ideal_theta, ideal_velocity)
    sensors.sample_offset = start


def fly_modes(profile: FlightProfile, derived: DerivedModel, trajectory: Trajectory, sensors: SensorData,
              layout: ErrorLayout, make_filter: FilterMaker, modes: Iterable[str],
              progress: Callable[[str], Progress] | None = None, piece_seconds: float = PIECE_SECONDS,
              record_every: int = 1, sinks: dict[str, Sink] | None = None,
              glue: str = "compiled", histories: dict[str, Any] | None = None) -> dict[str, RunResult]:
    """Fly ``modes`` in lockstep over one pass of the sensor data (module docstring); mode -> its result.

    ``progress(mode)`` makes each mode's progress callback; ``sinks[mode]``
    receives each recorded row as it is made (an incremental writer).  A held
    trajectory is flown the same way (its increments are sliced, not generated).
    ``glue="compiled"`` (default) flies the generated C filter in the compiled
    loop (:mod:`modelgen.simulation.native_loop`) where the sensor and filter
    allow it (and no sink is asked for), else the Python loop; ``"python"``
    always flies the Python loop.  ``histories[mode]`` (a
    :class:`~modelgen.simulation.history.CsvHistory`) receives each piece's
    recorded rows as soon as the piece is flown.
    """
    histories = histories or {}
    sensor = profile.aiding_sensor
    if not hasattr(sensor, "filter_loop"):
        raise ModelError(f"aiding sensor {sensor.name!r} has no filter_loop(): it can fly a held trajectory only")
    sinks = sinks or {}
    if glue not in GLUES:
        raise ModelError(f"streaming: unknown glue {glue!r} (choose from {', '.join(GLUES)})")
    native = glue == "compiled" and not sinks and native_supported(sensor, make_filter)
    loops: list[Any] = [
        sensor.native_loop(profile, derived, trajectory, sensors, layout, make_filter, mode,
                           progress(mode) if progress else None, record_every=record_every) if native else
        sensor.filter_loop(profile, derived, trajectory, sensors, layout, make_filter, mode,
                           progress(mode) if progress else None, record_every=record_every, sink=sinks.get(mode))
        for mode in modes
    ]
    n_cycles = len(trajectory.truth) - 1
    cursor = sensors.imu_stream.cursor() if sensors.streamed else None
    ranges = list(pieces(n_cycles, cycles_per_piece(trajectory, piece_seconds)))
    with ThreadPoolExecutor(max_workers=1) as prefetch:
        # a streamed trajectory's next piece of ideal increments is generated (compiled, without the GIL)
        # while this one flies: the same numbers, made on the second core if there is one
        coming = prefetch.submit(ideal_piece, trajectory, *ranges[0]) if cursor is not None and ranges else None
        for index, (first, last) in enumerate(ranges):
            if cursor is not None:
                ideal = coming.result()
                if index + 1 < len(ranges):
                    coming = prefetch.submit(ideal_piece, trajectory, *ranges[index + 1])
                load_piece(sensors, cursor, first, last, ideal)
            for loop in loops:
                written = loop.recorded if first > 1 else 0  # the first piece also writes the row at t = 0
                loop.run(first, last)
                if loop.mode in histories:
                    histories[loop.mode].write(loop.result, written, loop.recorded)
    return {loop.mode: loop.result for loop in loops}
