"""A flight's truth and IMU errors, made in background threads while the filter model is derived.

``modelgen simulate`` starts them (:func:`start_flight`) before it derives the
model, so that the derivation, the imports after it and the filter's code
generation overlap them; the figure process (:mod:`modelgen.simulation.figure_process`)
is forked first, while no thread runs.
"""

from __future__ import annotations

import threading
import time
from concurrent.futures import Future
from typing import Any, Callable

import numpy as np

from modelgen.simulation.figure_process import FigureProcess
from modelgen.simulation.flight import imu_error_stream
from modelgen.simulation.scenario import FlightProfile
from modelgen.simulation.trajectory import Trajectory, generate_trajectory, sample_counts


def timed(function: Callable, *args: Any) -> tuple[Any, float]:
    """``function(*args)`` and the seconds it took."""
    start = time.perf_counter()
    return function(*args), time.perf_counter() - start


def in_background(function: Callable, *args: Any) -> tuple[Future, threading.Thread]:
    """``timed(function, *args)`` started in a daemon thread: its future and the thread.

    A daemon thread, not a pool's: if the caller fails before asking for the
    result (a model that does not derive), the process exits at once instead
    of waiting for the work to finish.
    """
    future: Future = Future()

    def run() -> None:
        if future.set_running_or_notify_cancel():
            try:
                future.set_result(timed(function, *args))
            except BaseException as error:  # handed to whoever asks for the result
                future.set_exception(error)

    thread = threading.Thread(target=run, name=f"modelgen-{function.__name__}", daemon=True)
    thread.start()
    return future, thread


def finished(started: tuple[Future, threading.Thread]) -> Any:
    """The result of work started by :func:`in_background` (its error raised), once its thread has ended."""
    future, thread = started
    result = future.result()
    thread.join()
    return result


class FlightStart:
    """A flight's truth and IMU errors, being made in two background threads (compiled code, no GIL held).

    Neither needs the filter model, so ``modelgen simulate`` starts them
    (:func:`start_flight`) before it derives the model, and the derivation,
    the imports after it and the filter's code generation overlap them.  When
    the aiding sensor does not read the truth position (the Doppler radar) the
    truth leaves it to the flight's pieces (``positions_in_pieces``), which
    integrate it anyway for the increments.  The
    IMU errors are the seed's first draws (:func:`~modelgen.simulation.flight.imu_error_stream`);
    :attr:`rng` continues from there once :meth:`imu_errors` has returned.
    Before the threads start (a process with threads running does not fork),
    the flight's :class:`FigureProcess` is forked (:attr:`figures`; None where
    it cannot be, or with ``figure_process=False``): it imports matplotlib
    while this process derives the model.
    """

    def __init__(self, profile: FlightProfile, seed: int, figure_process: bool = True):
        self.profile, self.seed = profile, seed
        self.figures = FigureProcess.start() if figure_process else None
        n_samples, record_every = sample_counts(profile.path, profile.imu_rate, 1.0 / profile.filter.period)
        self.rng = np.random.default_rng(seed)
        # the truth positions are integrated by the flight's pieces (once, not twice) unless the aiding sensor
        # reads them when its record is drawn, before the flight
        later = not getattr(profile.aiding_sensor, "reads_truth_position", True)
        self._truth = in_background(generate_trajectory, profile.path, profile.imu_rate, 1.0 / profile.filter.period,
                                     True, later)
        self._imu = in_background(imu_error_stream, profile, n_samples, record_every, self.rng)

    def trajectory(self) -> tuple[Trajectory, float]:
        """The streamed trajectory (truth rows; increments come piece by piece) and the seconds it took."""
        return finished(self._truth)

    def imu_errors(self) -> tuple[Any, float]:
        """The :class:`~modelgen.simulation.imu.ImuErrorStream` and the seconds its draws took."""
        return finished(self._imu)


def start_flight(profile: FlightProfile, seed: int, figure_process: bool = True) -> FlightStart:
    """Start making ``profile``'s truth and drawing its IMU errors (seed ``seed``) now, and (``figure_process``)
    fork the process that will draw its figures; see :class:`FlightStart`."""
    return FlightStart(profile, seed, figure_process)
