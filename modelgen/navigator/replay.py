"""One replay end to end: read, generate the filter, fly, measure, write report/replay/."""

from __future__ import annotations

import time  # noqa: I001
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np

from modelgen.errors import ModelError
from modelgen.navigator.cnav import GeneratedC, cached_c_navigator, fly_c, rest_capacity, window_capacity
from modelgen.navigator.alignment import alignment_note
from modelgen.navigator.config import NavigatorConfig, load_config
from modelgen.navigator.errorstate import model_path
from modelgen.navigator.logs import read_gnss, read_imu
from modelgen.navigator.metrics import (errors_against_reference, pooled_consistency, schedule_record, summary,
                                        velocity_latency)
from modelgen.navigator.navigator import Flight, fly, prepare
from modelgen.navigator.spec import spec_of
from modelgen.navigator.report import report_files
from modelgen.navigator.smoother import ForwardRecord, GeneratedPython, backward_pass, smooth_flight, smoothing_summary
from modelgen.fileio.output import write_atomically


@dataclass
class ReplayResult:
    """The flight, its summary and where the report went."""

    config: NavigatorConfig
    flight: Flight
    summary: dict
    folder: Path | None
    timings: dict[str, float]
    #: replay --smooth: the RTS-smoothed flight (same epochs as the recorded Python forward pass), else None
    smoothed: Flight | None = None

    def targets(self) -> list[dict]:
        """The stated targets and whether this flight met them (:func:`modelgen.navigator.report.targets`)."""
        from modelgen.navigator.report import targets

        return targets(self.summary, self.timings)

    def __repr__(self) -> str:
        missed = [t["quantity"] for t in self.targets() if t["met"] is False]
        return (f"<ReplayResult {self.config.name!r}: {self.summary['outage_count']} outages, end-of-outage "
                f"horizontal error RMS {self.summary['horizontal_error_end_rms_m']:.2f} m; "
                f"{len(missed)} target(s) missed{': ' + '; '.join(missed) if missed else ''}>")

    def _repr_markdown_(self) -> str:
        """What a notebook shows: the targets, reached against stated, met or missed."""
        lines = [f"**Replay `{self.config.name}`** ({self.summary['navigator']} navigator)"
                 + (f", report in `{self.folder}`" if self.folder else ""), "",
                 "| quantity | reached | target | |", "|---|---|---|---|"]
        lines += [f"| {t['quantity']} | {t['reached']} | {t['target']} | "
                  f"{'' if t['met'] is None else 'met' if t['met'] else 'missed'} |" for t in self.targets()]
        return "\n".join(lines) + "\n"


NAVIGATORS = ("c", "python", "both")
#: Stated tolerance of the single-precision filter build against the double C navigator, antenna position, every epoch.
EMBEDDED_TOLERANCE_M = 0.01


def run_replay(config_path: str | Path, out: Path | None, echo: Callable[[str], None] = print,
               with_figures: bool = True, force: bool = False, navigator: str = "c",
               embedded: bool = False, smooth: bool = False) -> ReplayResult:
    """Fly the configuration's logs and, if ``out`` is given, write the report folder there atomically.

    ``navigator``: the generated C navigator (compiled now), the Python
    reference, or both (the report then states their largest difference; the
    C flight is the one reported).  ``smooth``: also run the RTS smoother over
    the Python navigator's recorded forward pass (flown for it if only the C
    flies) and report the smoothed errors beside that forward pass's
    (:mod:`modelgen.navigator.smoother`).
    """
    if navigator not in NAVIGATORS:
        raise ModelError(f"replay: unknown navigator {navigator!r} (choose from {', '.join(NAVIGATORS)})")
    timings: dict[str, float] = {}
    start = time.perf_counter()
    config = load_config(config_path)
    echo(f"replay {config.name}: reading {config.imu_file.name} and {config.gnss_file.name}")
    imu = read_imu(config.imu_source, config.gap_factor, config.gap_action)
    gnss = read_gnss(config.gnss_source)
    inputs = prepare(config, imu, gnss)
    for note in inputs.notes:
        echo(f"  note: {note}")
    timings["read_s"] = time.perf_counter() - start
    model_file = model_path(config.model, config.origin("model"), config.where("model"))
    mark = time.perf_counter()
    from modelgen.derivation.symbolic import derive
    from modelgen.model.loading import load_model

    model = load_model(model_file)  # the one load of this replay: checked, then derived once
    check_navigation_model(config, model_file, model)
    flights: dict[str, Flight] = {}
    echo(f"  deriving {config.model} (once) with modelgen")
    # the one derivation of this replay: the Python navigator, the C and the embedded build all use it
    spec = spec_of(derive(model), model_file, with_python=navigator in ("python", "both"))
    spec.check_config(config)
    timings["generate_python_s"] = time.perf_counter() - mark
    if navigator in ("python", "both"):
        mark = time.perf_counter()
        state = {"next": 0.0}

        def progress(fraction: float) -> None:
            if fraction >= state["next"]:
                echo(f"  flying (Python): {100 * fraction:5.1f} %  ({time.perf_counter() - mark:.1f} s)")
                state["next"] = fraction + 0.25

        flights["python"] = fly(config, inputs, spec, progress, record=ForwardRecord() if smooth and navigator == "python" else None)
        timings["fly_python_s"] = time.perf_counter() - mark
    if navigator in ("c", "both"):
        mark = time.perf_counter()
        compiled, cached = cached_c_navigator(spec, echo, rest_capacity(config, inputs.time),
                                              window_capacity(config, inputs.time))
        timings["generate_compile_c_s"] = 0.0 if cached else time.perf_counter() - mark
        mark = time.perf_counter()
        echo("  flying (C)")
        flights["c"], timings["fly_c_cpu_s"] = fly_c(config, inputs, compiled, record=smooth)
        timings["fly_c_s"] = time.perf_counter() - mark
    if embedded:
        if "c" not in flights:
            raise ModelError("replay: --embedded compares with the C navigator (use --navigator c or both)")
        from modelgen.navigator.cnav import log_arrays
        from modelgen.navigator.embedded import embedded_replay

        mark = time.perf_counter()
        echo("  Cortex-M4F build (float filter) and the log under qemu-arm")
        arm_arrays = log_arrays(config, inputs, spec)
        arm = embedded_replay(spec, arm_arrays, flights["c"].outputs)
        timings["embedded_s"] = time.perf_counter() - mark
    flight = flights["c"] if "c" in flights else flights["python"]
    timings["fly_s"] = timings.get("fly_c_s", timings.get("fly_python_s", 0.0))
    errors = errors_against_reference(flight, inputs.gnss)
    result = summary(flight, errors, inputs.gnss)
    result["navigator"] = "c" if "c" in flights else "python"
    result["model"] = {"name": spec.name, "file": str(model_file), "states": spec.n_states, "frame": spec.frame,
                       "blocks": sorted(spec.blocks)}
    note = alignment_note(config, flight.alignment, flight.first_epoch) if flight.alignment else None
    if note:
        echo(f"  warning: {note}")
        result["notes"].append(note)
    # consistency over schedules: the configured one and every evaluation.schedules entry, same navigator and log
    schedules = [schedule_record("configured", flight, errors, inputs.gnss, config.target_end_rms_m)]
    mark = time.perf_counter()
    for entry in config.evaluation_schedules:
        again = replace(config, outage_schedule=entry.schedule, outage_windows=entry.windows)
        if "c" in flights:
            other = fly_c(again, inputs, compiled)[0]
        else:
            other = fly(again, inputs, spec)
        schedules.append(schedule_record(entry.name, other, errors_against_reference(other, inputs.gnss), inputs.gnss,
                                         entry.target_end_rms_m))
    if config.evaluation_schedules:
        timings["fly_evaluation_schedules_s"] = time.perf_counter() - mark
        echo(f"  flew {len(config.evaluation_schedules)} further outage schedule(s) for the consistency statistics")
    result["schedules"] = schedules
    result["tuning"] = dict(config.tuning)  # which numbers of the configuration were tuned, and how
    result["consistency_pooled"] = pooled_consistency(schedules)
    result["evaluation_targets"] = {"target_nees_mean": list(config.target_nees_mean) if config.target_nees_mean
                                    else None, "target_inside_95_fraction": config.target_inside_95_fraction}
    if len(flights) == 2:
        result["c_python_max_difference_m"] = max_position_difference(flights["c"], flights["python"])
        echo(f"  C and Python trajectories: largest difference {result['c_python_max_difference_m']:.3g} m")
    if embedded:
        result["embedded"] = {"cortex_m4f_text_bytes": arm.text, "cortex_m4f_data_bytes": arm.data,
                              "cortex_m4f_bss_bytes": arm.bss, "navigator_struct_bytes": arm.navigator_struct_bytes,
                              "rest_max_samples": arm_arrays.rest_max, "window_max_samples": arm_arrays.window_max,
                              "worst_case_stack_bytes": arm.worst_case_stack, "heap_or_stdio_symbols": arm.forbidden_symbols,
                              "qemu_max_position_difference_m": arm.max_position_difference_m,
                              "tolerance_m": EMBEDDED_TOLERANCE_M}
        echo(f"  qemu-arm (float filter) against the double C navigator: largest difference "
             f"{arm.max_position_difference_m:.2g} m")
    passes = None
    if smooth:
        mark = time.perf_counter()
        # the forward record of the reported flight: the C's (its own buffers) when the C flew, else the Python's;
        # the backward pass is the model's generated one in the same language
        recorded = flights["c"] if "c" in flights else flights["python"]
        backward = GeneratedC(compiled) if "c" in flights else GeneratedPython(spec.module)
        passes, backward_s = _smoothed_passes(recorded, echo, backward)
        timings["smooth_backward_s"] = backward_s
        result["smoothed"] = smoothing_summary(*passes, inputs.gnss, config.target_smoothed_outage_rms_m,
                                               config.target_smoothed_outage_max_m, backward.name, backward_s)
        timings["smooth_s"] = time.perf_counter() - mark
        echo(f"  smoothed (RTS over {result['smoothed']['steps']} steps): horizontal RMS over the outage epochs "
             f"{result['smoothed']['smoothed']['horizontal_error_outage_rms_m']:.3f} m (forward "
             f"{result['smoothed']['forward']['horizontal_error_outage_rms_m']:.3f} m)"
             if result["smoothed"]["smoothed"]["horizontal_error_outage_rms_m"] is not None else "  smoothed (no outages)")
    folder = None
    if out is not None:
        files = report_files(flight, errors, result, config, inputs.gnss, timings, velocity_latency(inputs.gnss),
                             with_figures, smoothed=passes)
        folder = write_atomically(Path(out), files, force=force)
    timings["total_s"] = time.perf_counter() - start
    return ReplayResult(config, flight, result, folder, timings, passes[1] if passes else None)


def _smoothed_passes(recorded: Flight, echo: Callable[[str], None], backward) -> tuple[tuple[Flight, Flight], float]:
    """((forward, smoothed), seconds of the backward pass alone) of a flight flown with its record.

    ``backward``: the model's generated backward pass (the C's in the navigator library when the C flew and
    recorded, else the generated Python's).
    """
    echo(f"  backward pass: {backward.name} on the {'C' if isinstance(backward, GeneratedC) else 'Python'} "
         "navigator's forward record")
    record = getattr(recorded, "forward_record", None)
    if record is None:
        raise ModelError("replay: the flight to smooth was flown without its forward record")
    mark = time.perf_counter()
    steps = backward_pass(record, backward)
    seconds = time.perf_counter() - mark
    return (recorded, smooth_flight(recorded, backward, steps)), seconds


#: The built-in navigator model; a model without a navigation: section flies only if its states are this model's.
BUILTIN_NAVIGATOR_MODEL = "ins_gps15_nav"


def check_navigation_model(config: NavigatorConfig, model_file: Path, model) -> None:
    """Refuse, in one line and before any code is generated or compiled, a model the navigator cannot fly.

    A model with a ``navigation:`` section is the navigator's to generate; a model without one flies only with
    the error states of the built-in navigator model, in its order (the hand-written error-state layout).
    ``model`` is the model file, loaded (the replay's one load); the built-in one is loaded only if it is another.
    """
    from modelgen.fileio.datafiles import read_yaml
    from modelgen.model.loading import load_model

    data = read_yaml(model_file, "model file")
    if "navigation" in data:
        return
    reference_file = model_path(BUILTIN_NAVIGATOR_MODEL, config.origin("model"), config.where("model"))
    reference = read_yaml(reference_file, "model file")
    if "navigation" in reference:
        wanted = None  # the built-in navigator model is a navigation model itself: so must every model be
    elif Path(reference_file).resolve() == Path(model_file).resolve():
        wanted = [s.name for s in model.states]
    else:
        wanted = [s.name for s in load_model(reference_file).states]
    states = [s.name for s in model.states]
    if wanted is not None and states == wanted:
        return
    need = ("a model with a navigation: section" if wanted is None else
            f"a model with a navigation: section, or the {len(wanted)} error states of {BUILTIN_NAVIGATOR_MODEL} "
            "in their order")
    raise ModelError(f"{config.where('model')}: model {config.model!r} ({model_file}) is not a navigation model the replay "
                     f"can fly: it needs {need}; this one has {len(states)} states ({', '.join(states[:4])}"
                     f"{', ...' if len(states) > 4 else ''}) and no navigation: section")


def max_position_difference(a: Flight, b: Flight) -> float:
    """Largest 3-D distance [m] between two flights' antenna positions at the same output epochs."""
    from modelgen.navigator.mechanization import radii

    if a.outputs.shape != b.outputs.shape or not np.array_equal(a.outputs[:, 0], b.outputs[:, 0]):
        raise ModelError("replay: the C and Python flights have different output epochs")
    rm, rn = radii(float(a.outputs[0, 1]))
    north = (a.outputs[:, 1] - b.outputs[:, 1]) * rm
    east = (a.outputs[:, 2] - b.outputs[:, 2]) * rn * np.cos(a.outputs[:, 1])
    up = a.outputs[:, 3] - b.outputs[:, 3]
    return float(np.sqrt(north**2 + east**2 + up**2).max())
