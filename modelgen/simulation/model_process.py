"""A flight's filter model, derived in a forked process: the flying process never imports sympy.

``modelgen simulate`` with the generated C filter reads of its derived model
only plain data: the model's outline (:class:`~modelgen.simulation.model_outline.ModelOutline`:
names and the structure of F, G and H), its states' units, the generated
filter's files, the error layout of the flight and, for a Monte Carlo study,
the set-up its workers receive (:class:`~modelgen.simulation.montecarlo.MonteCarloSetup`).
:class:`ModelProcess` makes them in a copy of the process forked before the
flight's threads start: the copy loads the model (pint), derives it (sympy),
generates the code and makes the layout, sends back a :class:`PreparedModel`
and leaves.  The flying process then holds none of sympy, pint or the
derivation (about 60 MiB of its peak resident memory for the paper's model,
``bench/bench_simulate_memory.py``), and its numbers are those of flying the
derived model itself: the same code, the same layout (read at the flight's
initial state, as the Monte Carlo workers read it), the same set-up digest.
Where there is no fork the model is prepared in this process.
"""

from __future__ import annotations

import os
import pickle
import signal
import sys
import threading
import traceback
from dataclasses import dataclass
from typing import Any, Mapping

from modelgen.errors import ModelError
from modelgen.simulation.error_layout import ErrorLayout
from modelgen.simulation.model_outline import ModelNames, ModelOutline
from modelgen.simulation.scenario import FlightProfile


@dataclass(frozen=True)
class PreparedModel:
    """What a flight with the generated C filter needs of its derived model, as plain data (module docstring).

    ``model`` (the model's names) and the structure of ``outline`` stand in
    for the derived model's; ``units`` maps each state to its unit;
    ``files`` is the generated filter's code (name -> text); ``layout`` the
    flight's error layout (holding ``outline``); ``symbolic`` the derived
    model pickled (:func:`~modelgen.simulation.montecarlo.symbolic_only`), for the Python loop a sensor
    without a compiled loop needs; ``monte_carlo`` the Monte Carlo set-up (None without runs).
    """

    outline: ModelOutline
    units: Mapping[str, str]
    files: Mapping[str, str]
    layout: ErrorLayout
    symbolic: bytes
    monte_carlo: Any = None

    @property
    def model(self) -> ModelNames:
        return self.outline.model

    def symbolic_model(self) -> Any:
        """The derived model itself (its symbolic matrices; unpickling imports sympy), for a flight that needs them."""
        return pickle.loads(self.symbolic)


def prepare_model(profile: FlightProfile, implementation: str, runs: int) -> PreparedModel:
    """Derive ``profile``'s filter model and make what the flight needs of it (:class:`PreparedModel`), here."""
    from modelgen.derivation.symbolic import derive
    from modelgen.model.loading import load_model
    from modelgen.simulation.filters import generated_filter_files
    from modelgen.simulation.montecarlo import caller_layout, study_setup, symbolic_only

    derived = derive(load_model(profile.filter.model))
    outline = ModelOutline.of(derived)
    setup = study_setup(profile, derived, implementation) if runs > 0 else None
    files = setup.code if setup is not None and setup.code is not None else generated_filter_files(derived)
    layout = setup.layout if setup is not None else caller_layout(profile, derived, outline)
    symbolic = setup.derived if setup is not None else pickle.dumps(symbolic_only(derived), protocol=pickle.HIGHEST_PROTOCOL)
    return PreparedModel(outline, {state.name: state.unit for state in derived.model.states}, files, layout, symbolic,
                         setup)


class ModelProcess:
    """:func:`prepare_model` running in a forked copy of this process; :meth:`result` waits for its answer.

    Fork it (:meth:`start`) while no other thread runs (a thread's locks
    would be copied held).  An error of the copy (a model that does not
    load or derive) is raised by :meth:`result` as it was raised there.
    """

    def __init__(self, profile: FlightProfile, implementation: str, runs: int):
        self.profile, self.implementation, self.runs = profile, implementation, runs
        self._pid: int | None = None
        self._connection: Any = None

    @classmethod
    def start(cls, profile: FlightProfile, implementation: str, runs: int) -> "ModelProcess":
        """Fork the copy that prepares the model now (where there is no fork, :meth:`result` prepares it here)."""
        process = cls(profile, implementation, runs)
        if not hasattr(os, "fork") or threading.active_count() > 1:
            return process
        from multiprocessing import Pipe

        here, there = Pipe(duplex=False)
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:  # the copy: prepare, answer, leave without running this process's exit handlers
            status = 1
            try:
                signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the caller's to handle
                here.close()
                try:
                    answer: tuple = ("prepared", prepare_model(profile, implementation, runs))
                except Exception as error:  # raised again by result(), in the caller
                    answer = ("failed", error, traceback.format_exc())
                try:
                    there.send(answer)
                except Exception:  # an error that does not pickle: its text
                    there.send(("failed", ModelError(str(answer[1])), answer[2]))
                status = 0
            except BaseException:
                traceback.print_exc()
            finally:
                os._exit(status)
        there.close()
        process._pid, process._connection = pid, here
        return process

    def result(self) -> PreparedModel:
        """The prepared model (the copy's error raised here)."""
        if self._pid is None:
            return prepare_model(self.profile, self.implementation, self.runs)
        try:
            answer = self._connection.recv()
        except EOFError:
            answer = None
        finally:
            self._connection.close()
            os.waitpid(self._pid, 0)
            self._pid = None
        if answer is None:
            raise ModelError(f"simulate: the process deriving {self.profile.filter.model!r} ended without an answer")
        if answer[0] == "failed":
            raise answer[1]
        return answer[1]

