"""Run histories written as they are made: one CSV file per correction mode, appended piece by piece.

The streaming driver (:func:`modelgen.simulation.streaming.fly_modes`) hands
each piece's newly recorded rows to a :class:`CsvHistory`, so a long flight's
histories reach the disk while it flies; the in-memory
:class:`~modelgen.simulation.filter_loop.RunResult` keeps the same rows (at
the rate ``record_every`` sets) for the report.  Columns: ``time_s``, the
corrected output (latitude_rad, longitude_rad, height_m, velocity_*_mps,
q0..q3), then per model state its estimation error and filter sigma (SI units
of the state), then ``nees``.  CSV through the standard library: the rows are a
few dozen numbers each, and no columnar-format package earns its install size
for that.

The files are opened in the caller's folder; ``modelgen simulate`` writes them
into the report's staging folder, which is committed atomically at the end
(:class:`modelgen.fileio.output.ReportUpdate`), so a failed run leaves no
half-written history behind.
"""

from __future__ import annotations

import csv
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator, TextIO

from modelgen.simulation.filter_loop import RunResult

OUTPUT_COLUMNS = ("latitude_rad", "longitude_rad", "height_m", "velocity_north_mps", "velocity_east_mps",
                  "velocity_down_mps", "q0", "q1", "q2", "q3")


def history_columns(state_names: list[str]) -> list[str]:
    """The header of a history file for a model with ``state_names``."""
    return (["time_s", *OUTPUT_COLUMNS] + [f"error_{name}" for name in state_names]
            + [f"sigma_{name}" for name in state_names] + ["nees"])


class CsvHistory:
    """One mode's history file, appended to with :meth:`write` (rows [start, stop) of a result)."""

    def __init__(self, path: Path, state_names: list[str]):
        self.path = Path(path)
        self.state_names = list(state_names)
        self._file: TextIO = open(self.path, "w", newline="", encoding="utf-8")
        self._writer = csv.writer(self._file)
        with self._naming_the_file():
            self._writer.writerow(history_columns(self.state_names))
        self.rows = 0

    @contextmanager
    def _naming_the_file(self) -> Iterator[None]:
        """An OSError of a write (a full disk: it names no file) names this history's file."""
        try:
            yield
        except OSError as exc:
            if exc.filename is None:
                raise OSError(exc.errno, exc.strerror or str(exc), str(self.path)) from exc
            raise

    def write(self, result: RunResult, start: int, stop: int) -> None:
        """Append the result's recorded rows [start, stop) (each row once, in order)."""
        with self._naming_the_file():
            for row in range(start, stop):
                self._writer.writerow([repr(float(result.times[row])), *map(repr, result.outputs[row].tolist()),
                                       *map(repr, result.estimation_error[row].tolist()),
                                       *map(repr, result.sigma[row].tolist()), repr(float(result.nees[row]))])
            self.rows += stop - start
            self._file.flush()

    def close(self) -> None:
        with self._naming_the_file():
            self._file.close()
