"""One replay end to end: read, generate the filter, fly, measure, write report/replay/."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from modelgen.navigator.config import NavigatorConfig, load_config
from modelgen.navigator.errorstate import generate_filter_module, model_path
from modelgen.navigator.logs import read_imu_csv, read_rtklib_pos
from modelgen.navigator.metrics import errors_against_reference, summary, velocity_latency
from modelgen.navigator.navigator import Flight, fly, prepare
from modelgen.navigator.report import report_files
from modelgen.output import write_atomically


@dataclass
class ReplayResult:
    """The flight, its summary and where the report went."""

    config: NavigatorConfig
    flight: Flight
    summary: dict
    folder: Path | None
    timings: dict[str, float]


def run_replay(config_path: str | Path, out: Path | None, echo: Callable[[str], None] = print,
               with_figures: bool = True, force: bool = False) -> ReplayResult:
    """Fly the configuration's logs and, if ``out`` is given, write the report folder there atomically."""
    timings: dict[str, float] = {}
    start = time.perf_counter()
    config = load_config(config_path)
    echo(f"replay {config.name}: reading {config.imu_file.name} and {config.gnss_file.name}")
    imu = read_imu_csv(config.imu_file, config.imu_columns, config.gap_factor)
    gnss = read_rtklib_pos(config.gnss_file)
    inputs = prepare(config, imu, gnss)
    timings["read_s"] = time.perf_counter() - start
    mark = time.perf_counter()
    echo(f"  generating the {config.model} filter with modelgen")
    module = generate_filter_module(model_path(config.model, config.path))
    timings["generate_s"] = time.perf_counter() - mark
    mark = time.perf_counter()
    state = {"next": 0.0}

    def progress(fraction: float) -> None:
        if fraction >= state["next"]:
            echo(f"  flying: {100 * fraction:5.1f} %  ({time.perf_counter() - mark:.1f} s)")
            state["next"] = fraction + 0.25

    flight = fly(config, inputs, module, progress)
    timings["fly_s"] = time.perf_counter() - mark
    errors = errors_against_reference(flight, inputs.gnss)
    result = summary(flight, errors, inputs.gnss)
    folder = None
    if out is not None:
        files = report_files(flight, errors, result, config, inputs.gnss, timings, velocity_latency(inputs.gnss),
                             with_figures)
        folder = write_atomically(Path(out), files, force=force)
    timings["total_s"] = time.perf_counter() - start
    return ReplayResult(config, flight, result, folder, timings)
